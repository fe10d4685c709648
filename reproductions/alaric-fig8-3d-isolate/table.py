"""Collect the runs of ``reproductions/alaric-fig8-3d-isolate/results`` (and the two stored ``fig8_mirror`` 3D runs they
control) into ``results.json`` and a markdown table (printed): epsilon, pairing by layer
(:func:`alaric_fig8_nn.layer_checks`), the bottom of the well, steps, stop reason, wall time, load averages.

    python reproductions/alaric-fig8-3d-isolate/table.py reproductions/alaric-fig8-3d-isolate/results
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
from ase.io import read

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from lib.alaric_fig8_nn import fig8_checks  # noqa: E402

# the runs stopped by hand (no summary.json): their settings, from run.sh
HAND_STOPPED = {
    "e_n26415_split1": dict(note="stage 0 (N = 5283, split 0 until its split at step 4000) of the N = 26 415 split-1 "
                                 "run, stopped by hand at the split"),
    "c_n26411_smooth1": dict(smooth_wall=1.0, note="continuation of fig8_mirror/3d_n26411, smooth wall L = 1, "
                                                   "stopped by hand after 300 steps"),
}

STORED = ("reproductions/alaric-fig8/results/3d_n2075_after", "reproductions/alaric-fig8/results/3d_n26411")


def row_of(folder):
    folder = Path(folder)
    summary = json.loads((folder / "summary.json").read_text()) if (folder / "summary.json").exists() else None
    uptime = folder.parent / f"{folder.name}.uptime"
    loads = uptime.read_text().split("\n") if uptime.exists() else []
    if summary is None:  # stopped by hand: its pairing trace only
        trace = json.loads((folder / "nn_trace.json").read_text())
        last = [e for e in trace if e["n"] == trace[0]["n"]][-1]  # its last check before any split
        first_paired = next((e["step"] for e in trace if e["edge_below_half"] + e["interior_below_half"] > 0), None)
        row = dict(last, mode="stopped by hand: its last check before any split", split=0, boundary="mirror",
                   steps=last["step"], stop_reason="killed", wall_time_s=last["wall"],
                   first_paired_check_step=first_paired, stages=sorted({e["n"] for e in trace}),
                   **HAND_STOPPED.get(folder.name, {}))
    elif "mode" in summary:  # reproductions/lib/alaric_fig8_isolate.py
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
    if summary is not None:  # the end state: particles outside the unit ball (a soft wall lets the outer layer out)
        r_p = np.linalg.norm(read(folder / "relaxed.extxyz").positions, axis=1)
        row.update(outside_ball=int(np.count_nonzero(r_p > 1.0)), r_max=float(r_p.max()))
    return row


def main():
    root = Path(sys.argv[1])
    folders = [Path(p) for p in STORED] + sorted(p for p in root.iterdir() if (p / "summary.json").exists()
                                                 or (p / "nn_trace.json").exists())
    rows = {str(f): row_of(f) for f in folders}
    energy = {p.stem: json.loads(p.read_text())["summary"] for p in sorted((root / "energy").glob("*.json"))}
    fd = {p.stem: [json.loads(line) for line in p.read_text().splitlines() if line.strip()]
          for p in sorted(root.glob("fd_check_*.jsonl"))}
    (root / "results.json").write_text(json.dumps(dict(runs=rows, energy_checks=energy, fd_checks=fd), indent=1))
    print("| run | N | split | edge / wall | steps | stop | eps | min NN/mean: edge | interior | "
          "pairs (< 0.5 of the mean) | paired r | closest to r = 0 | r < 0.15 | outside r = 1 | wall s |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for f, r in rows.items():
        pr = r.get("paired_r_range")
        wall = ("smooth wall L = %g" % r["smooth_wall"] if r.get("smooth_wall") else
                "linear wall x%g" % r["wall_length_factor"] if r.get("wall_length_factor") else "linear wall")
        extra = ", CFL %g" % r["cfl"] if r.get("cfl", 0.25) != 0.25 else ""
        print(f"| {Path(f).parent.name}/{Path(f).name} | {r['n']} | {r['split']} | {r['boundary']}, {wall}{extra} | "
              f"{r['steps']} | {r['stop_reason']} | {r['epsilon']:.2e} | {r['edge_nn_min_over_mean']:.3f} | "
              f"{r['interior_nn_min_over_mean']:.3f} | {r['edge_below_half'] + r['interior_below_half']} | "
              f"{'-' if pr is None else f'{pr[0]:.2f}-{pr[1]:.2f}'} | {r['r_min']:.3f} | "
              f"{r['particles_within_0_15']} | "
              f"{r.get('outside_ball', '-')} | {r['wall_time_s']:.0f} |")
    print()
    print("| energy check (300 steps from a_n2075_split1) | time span | steps with E_tot up | sum of increases | "
          "per unit time | largest | max speed / c_s |")
    print("|---|---|---|---|---|---|---|")
    for k, e in energy.items():
        print(f"| {k} | {e['time']:.2f} | {e['steps_increasing']} of {e['steps'] - 1} | {e['sum_of_increases']:.3g} | "
              f"{e['increase_per_time']:.3g} | {e['largest_increase']:.3g} | {e['v_max']:.2f} |")


if __name__ == "__main__":
    main()
