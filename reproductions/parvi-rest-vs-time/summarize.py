"""Tables of the rows of every ``*.json`` of this folder into ``summary.md``.

    PYTHONPATH=. .venv/bin/python reproductions/parvi-rest-vs-time/summarize.py
"""
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from lib.results_io import read_json as load_json  # noqa: E402

HERE = Path(__file__).resolve().parent / "results"  # this entry's results
TAILS = dict(funnel=("share_below_m3", "share_below_m6"), banana=("share_abs_above_15", "share_abs_above_20"))
SPREAD = dict(funnel="x1_rms_over_width", banana="u_rms")


def fmt(value, digits=3):
    if value is None:
        return "-"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return f"{value:.{digits}g}"
    return str(value)


def main():
    lines = ["# Every row of this folder's JSON files (made by summarize.py)", ""]
    for path in sorted(HERE.glob("*.json*")):
        rows = load_json(path).get("rows")
        if not rows or "target" not in rows[0]:
            continue
        lines += [f"## {path.name}", "",
                  "| target | M | seed | variant | steps | time | E / iid | kinetic | converged | x0 mean | x0 q0.05 "
                  "(true) | tail shares (true) | spread per x0 bin (true 1) | H / width per bin | n / n_true per bin | git, load |",
                  "| " + " | ".join(["---"] * 16) + " |"]
        for row in rows:
            diag = row.get("diagnostics")
            if diag:
                t1, t2 = TAILS[row["target"]]
                q = diag["x0"]["quantiles"]["0.05"]
                bins = diag["bins"]
                spread = " ".join(fmt(b[SPREAD[row["target"]]], 2) for b in bins)
                width = " ".join(fmt(b["h_over_width_median"], 2) for b in bins)
                counts = " ".join(f"{b['n']}/{b['n_true']:.0f}" for b in bins)
                extra = [fmt(diag["x0"]["mean"]), f"{q[0]:.2f} ({q[1]:.2f})",
                         f"{diag[t1][0]:.3f}, {diag[t2][0]:.3f} ({diag[t1][1]:.3f}, {diag[t2][1]:.3f})",
                         spread, width, counts]
            else:
                extra = ["-"] * 6
            variant = row["variant"] + "".join(f", {k}={row[k]:g}" for k in ("n_neighbours", "local_growth")
                                               if row.get(k) is not None)
            variant += ", i.i.d. start" if row.get("start") == "iid" else ""
            lines.append("| " + " | ".join([row["target"], str(row["m"]), str(row["seed"]), variant,
                                             str(row["steps"]), fmt(row.get("sim_time_median")),
                                             fmt(row.get("ratio_to_iid")), fmt(row.get("kinetic")),
                                             fmt(row.get("converged"))] + extra
                                            + [f"{row['git']}, {row['load']:.1f}"]) + " |")
        lines.append("")
    energies = json.loads((HERE / "snapshot_energy.json").read_text())["rows"]
    lines += ["## snapshot_energy.json: the model energy E of the checkpoints (lower = nearer the resting state)", "",
              "| snapshot file | steps | E | rms residual acceleration |", "| --- | --- | --- | --- |"]
    lines += [f"| {r['file']} | {r['steps']} | {r['energy']:.5f} | {r['residual_force_rms']:.3g} |" for r in energies]
    (HERE / "summary.md").write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
