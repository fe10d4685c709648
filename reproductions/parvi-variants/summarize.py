"""Table of ``results.json`` (and the seed-0 scans) -> ``summary.md``: energy distance over i.i.d. per variant.

    .venv/bin/python reproductions/parvi-variants/summarize.py
"""
import json
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent / "results"  # this entry's results
FILES = ["results.json", "scan_scalar.json", "scan_critical.json", "scan_critical_median.json", "funnel_m100.json"]


def table(rows):
    groups = {}
    for r in rows:
        groups.setdefault((r["target"], r["variant"]), []).append(r)
    lines = ["| target | variant | seeds | energy / i.i.d. (each seed) | mean | max | median time | converged | "
             "friction (rates) | git | load |", "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for (target, variant), group in groups.items():
        group = sorted(group, key=lambda r: r["seed"])
        ratios = [r.get("ratio_to_iid", np.nan) for r in group]
        each = " / ".join("div" if "error" in r else f"{r['ratio_to_iid']:.3g}" for r in group)
        finite = [x for x in ratios if np.isfinite(x)]
        mean = f"{np.mean(finite):.3g}" if len(finite) == len(group) else "div"
        worst = f"{np.max(finite):.3g}" if len(finite) == len(group) else "div"
        times = [r["sim_time_median"] for r in group if "sim_time_median" in r]
        rates = group[0].get("friction_rates")
        friction = (f"{group[0].get('friction')}" + (f" ({', '.join(f'{x:.3g}' for x in rates)})" if rates else "")
                    if "friction" in group[0] else "-")
        if isinstance(group[0].get("friction"), float):
            friction = f"{group[0]['friction']:.3g}"
        lines.append(f"| {target} | {variant} | {','.join(str(r['seed']) for r in group)} | {each} | {mean} | "
                     f"{worst} | {np.median(times) if times else float('nan'):.3g} | {sum(bool(r.get('converged')) for r in group)}/"
                     f"{len(group)} | {friction} | {group[0]['git']} | "
                     f"{min(r['load'] for r in group):.1f}-{max(r['load'] for r in group):.1f} |")
    return lines


def main():
    out = ["# SPH-ParVI variants: energy distance over i.i.d. (M = 500, 1000 evaluations per particle)", "",
           "Made by `summarize.py` from the files named in each section; the commands are in README.md.", ""]
    for name in FILES:
        path = HERE / name
        if not path.exists():
            continue
        rows = json.loads(path.read_text())["rows"]
        tags = sorted({r.get("tag", "") for r in rows})
        out += [f"## `{name}` ({'; '.join(tags)})", ""] + table(rows) + [""]
    (HERE / "summary.md").write_text("\n".join(out))
    print("\n".join(out))


if __name__ == "__main__":
    main()
