"""Tables of this folder's result files (steps.json, coarse.json, score_every.json, diagnose_coarse.json,
ring_default.json) as ``summary.md``: energy distance over i.i.d. (2000 points, seed + 500) per seed.

    .venv/bin/python reproductions/parvi-banana-m2000/summarize.py
"""
import json
from pathlib import Path

HERE = Path(__file__).resolve().parent / "results"  # this entry's results


def rows(name):
    path = HERE / name
    return json.loads(path.read_text())["rows"] if path.exists() else []


def table(data, title):
    keys = sorted({(r["target"], r["variant"], r["steps"]) for r in data}, key=str)
    lines = [f"## {title}", "", "| target | variant | budget (score evaluations per particle) | SPH steps | seed: over "
             "i.i.d. | measured evaluations per particle | time covered (median particle) | wall [s] | load |",
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for target, variant, steps in keys:
        sel = sorted((r for r in data if (r["target"], r["variant"], r["steps"]) == (target, variant, steps)),
                     key=lambda r: r["seed"])
        cell = ", ".join(f"{r['seed']}: {r['ratio_to_iid']:.3g}" if "ratio_to_iid" in r else f"{r['seed']}: diverged"
                         for r in sel)
        evals = ", ".join(f"{r.get('evaluations_per_particle', float('nan')):.0f}" for r in sel)
        sph_steps = sel[0].get("sph_steps", steps)
        sim = ", ".join(f"{r.get('sim_time_median', float('nan')):.0f}" for r in sel)
        wall = ", ".join(f"{r.get('wall', float('nan')):.0f}" for r in sel)
        load = ", ".join(f"{r['load']:.1f}" for r in sel)
        lines.append(f"| {target} | {variant} | {steps} | {sph_steps} | {cell} | {evals} | {sim} | {wall} | {load} |")
    return lines + [""]


def main():
    out = ["# M = 2000, SPH-ParVI alone: summary of the result files", "",
           "Energy distance over that of 2000 i.i.d. points (seed + 500), as `bench_sampling.py`. Made by "
           "`summarize.py` from the JSON files named in each heading.", ""]
    for name, title in (("steps.json", "More steps (steps.json): is the banana limited by the time covered?"),
                        ("coarse.json", "Coarse to fine, k = 4, share 0.5 (coarse.json)"),
                        ("score_every.json", "The score held over 4 SPH steps (score_every.json)"),
                        ("ring_default.json", "The default on the ring (ring_default.json)")):
        data = rows(name)
        if data:
            out += table(data, title)
    diag = rows("diagnose_coarse.json")
    if diag:
        out += ["## Where the coarse-to-fine error comes from (diagnose_coarse.json)", "",
                "| target | seed | coarse level (500 points) over i.i.d. of 500 | the same over i.i.d. of 2000 | "
                "children after the split | fine level after 500 / 1000 / 2000 steps | coarse time | fine times |",
                "| --- | --- | --- | --- | --- | --- | --- | --- |"]
        for r in diag:
            fine = " / ".join(f"{v['over_iid']:.3g}" for v in r["fine"].values())
            times = " / ".join(f"{v['time']:.0f}" for v in r["fine"].values())
            out.append(f"| {r['target']} | {r['seed']} | {r['coarse_over_iid_own_size']:.3g} | "
                       f"{r['coarse_over_iid_m']:.3g} | {r['children_over_iid']:.3g} | {fine} | "
                       f"{r['coarse_time']:.0f} | {times} |")
        out.append("")
    (HERE / "summary.md").write_text("\n".join(out))
    print("\n".join(out))


if __name__ == "__main__":
    main()
