"""summary.md from results.json: energy distance relative to i.i.d. per target, step rule, Courant factor and growth limit.

    .venv/bin/python reproductions/parvi-steps/summarize.py
"""
import json
from collections import defaultdict
from pathlib import Path

HERE = Path(__file__).resolve().parent / "results"  # this entry's results
rows = json.loads((HERE / "results.json").read_text())["rows"]
latest = {}  # a configuration run again with the same seed (deterministic): the last row
for r in rows:
    latest[(r["target"], r["time_step"], r["courant"], r.get("growth"), r["seed"])] = r
groups = defaultdict(list)
for key, r in latest.items():
    groups[key[:4]].append(r)
lines = ["| target | time_step | courant | growth | seeds | energy / i.i.d. (each seed) | mean | median dt / min dt | "
         "median time | converged |", "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
for (target, mode, courant, growth), rs in sorted(groups.items(), key=lambda kv: (kv[0][0], kv[0][1], kv[0][2],
                                                                                  kv[0][3] or 0)):
    ratios = [r["ratio_to_iid"] for r in rs]
    lines.append(f"| {target} | {mode} | {courant} | {growth or '-'} | {','.join(str(r['seed']) for r in rs)} | "
                 f"{' / '.join(f'{x:.3g}' for x in ratios)} | {sum(ratios) / len(ratios):.3g} | "
                 f"{sum(r['dt_median'] / r['dt_min'] for r in rs) / len(rs):.3g} | "
                 f"{sum(r['sim_time_median'] for r in rs) / len(rs):.3g} | "
                 f"{sum(bool(r['converged']) for r in rs)}/{len(rs)} |")
(HERE / "summary.md").write_text("\n".join(lines) + "\n")
print("\n".join(lines))
