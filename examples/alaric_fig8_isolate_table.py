"""Collect the runs of ``examples/results/alaric/fig8_3d_isolate`` (and the two stored ``fig8_mirror`` 3D runs they
control) into ``results.json`` and a markdown table (printed): epsilon, pairing by layer (:func:`alaric_fig8_nn.layer_checks`),
the bottom of the well, steps, stop reason, wall time, load averages.

    python examples/alaric_fig8_isolate_table.py examples/results/alaric/fig8_3d_isolate
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from alaric_fig8_nn import fig8_checks  # noqa: E402

STORED = ("examples/results/alaric/fig8_mirror/3d_n2075_after", "examples/results/alaric/fig8_mirror/3d_n26411")


def row_of(folder):
    folder = Path(folder)
    summary = json.loads((folder / "summary.json").read_text())
    uptime = folder.parent / f"{folder.name}.uptime"
    loads = uptime.read_text().split("\n") if uptime.exists() else []
    if "mode" in summary:  # examples/alaric_fig8_isolate.py
        trace = json.loads((folder / "nn_trace.json").read_text())
        first_paired = next((e["step"] for e in trace if e["edge_below_half"] + e["interior_below_half"] > 0), None)
        row = dict(summary, first_paired_check_step=first_paired, stages=sorted({e["n"] for e in trace}))
        row["wall_time_s"] = summary["wall_time_s"]
    else:  # a sphrelax density folder
        checks = fig8_checks(folder)
        layers = checks.pop("layers")
        row = dict(checks, **{k: v for k, v in layers.items() if k not in checks}, mode="cli",
                   split=summary["splits"], stop_reason=checks.pop("stop"), first_paired_check_step=None,
                   command=" ".join(["sphrelax density"] + [f"--{k.replace('_', '-')} {v}" for k, v in
                                                             summary["arguments"].items() if k not in ("command",)]))
    row["uptime_start_end"] = [s.strip() for s in loads if s.strip()]
    return row


def main():
    root = Path(sys.argv[1])
    folders = [Path(p) for p in STORED] + sorted(p for p in root.iterdir() if (p / "summary.json").exists())
    rows = {str(f): row_of(f) for f in folders}
    (root / "results.json").write_text(json.dumps(rows, indent=1))
    print("| run | N | split | boundary | steps | stop | eps | min NN/mean: edge | interior | pairs (< 0.5) edge | "
          "paired r | closest to r = 0 | r < 0.15 | wall s |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for f, r in rows.items():
        pr = r.get("paired_r_range")
        print(f"| {Path(f).parent.name}/{Path(f).name} | {r['n']} | {r['split']} | {r['boundary']} | {r['steps']} | "
              f"{r['stop_reason']} | {r['epsilon']:.2e} | {r['edge_nn_min_over_mean']:.3f} | "
              f"{r['interior_nn_min_over_mean']:.3f} | {r['edge_below_half']} | "
              f"{'-' if pr is None else f'{pr[0]:.2f}-{pr[1]:.2f}'} | {r['r_min']:.3f} | {r['particles_within_0_15']} | "
              f"{r['wall_time_s']:.0f} |")


if __name__ == "__main__":
    main()
