"""KE of each start averaged over time windows of one stored run: describes where a run's average comes from.

    python reproductions/lib/ke_windows.py reproductions/bipi-wedge-bisph/results/ke_dx001_t20.json.gz

Writes ``windows{tag}.json`` and the figure ``ke{tag}.png`` (KE(t) of each start, log scale, as the paper's
Fig. 14) beside the KE file: for each start the trapezoid mean of KE(t) over ``[0, 1]`` s,
``[1, T]`` and ``[0, T]`` (``T`` the run's end) and the final KE, and the Cartesian/BIPI ratio of each. The
verdict of a run stays its declared measure, the KE averaged over the whole run (``summary{tag}.json``).
"""
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from lib.results_io import read_json, write_json  # noqa: E402


def window_mean(t, ke, lo, hi):
    """Trapezoid mean of ``ke`` over the records with ``lo <= t <= hi``."""
    t, ke = np.asarray(t), np.asarray(ke)
    keep = (t >= lo - 1e-9) & (t <= hi + 1e-9)
    return float(np.trapezoid(ke[keep], t[keep]) / (t[keep][-1] - t[keep][0]))


def plot(curves, png):
    """KE(t) of each start on a log axis."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ase_sphrelax.plotting import save_figure

    fig, ax = plt.subplots(figsize=(6, 3.6))
    for name, c in curves.items():
        t, ke = np.asarray(c["t"]), np.asarray(c["ke"])
        ax.semilogy(t[ke > 0], ke[ke > 0], label=name)  # the start at rest (KE 0) left out
    ax.set_xlabel("t (s)")
    ax.set_ylabel("KE (J/m)")
    ax.legend()
    fig.tight_layout()
    save_figure(fig, png)


def main(argv=None):
    path = Path((argv or sys.argv[1:])[0])
    curves = read_json(path)
    out = {}
    for name, c in curves.items():
        end = float(c["t"][-1])
        out[name] = dict(first_second=window_mean(c["t"], c["ke"], 0.0, 1.0),
                         after_first_second=window_mean(c["t"], c["ke"], 1.0, end),
                         whole_run=window_mean(c["t"], c["ke"], 0.0, end), final=float(c["ke"][-1]), t_end=end)
    if {"cartesian", "bipi"} <= set(out):
        out["ratio_cartesian_over_bipi"] = {k: out["cartesian"][k] / out["bipi"][k] for k in
                                            ("first_second", "after_first_second", "whole_run", "final")}
    tag = path.name[len("ke"):-len(".json.gz")]
    write_json(path.parent / f"windows{tag}.json", out)
    plot(curves, path.parent / f"ke{tag}.png")
    print(out)


if __name__ == "__main__":
    main()
