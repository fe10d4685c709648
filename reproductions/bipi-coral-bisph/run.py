"""BIPI Figs. 15-18 in BISPH: BIPI2D's own coral tank at rest from a Cartesian and a BIPI start.

    python reproductions/bipi-coral-bisph/run.py [--dx 0.02] [--t-end 2.0]
    python reproductions/bipi-coral-bisph/run.py --t-end 5.0 --tag _t5     # the longer check
    python reproductions/bipi-coral-bisph/run.py --wall-band 0 --t-end 0.5 --tag _band0
    python reproductions/bipi-coral-bisph/run.py --fig18 30 100 1000 --t-end 0.5 --tag _fig18
    python reproductions/bipi-coral-bisph/run.py --plot      # results/ke.png and results/window.json
    python reproductions/bipi-coral-bisph/run.py --plot pointwise   # results/ke_pointwise.png, window_pointwise.json

Geometry: ``coral_tank.edges`` beside this file, converted by ``reproductions/lib/nastran.py`` from
BIPI2D's ``CoralInTank/bulkBdry1D.dat`` (commit 3b28f85, MIT): a trapezoidal tank (left wall x = 0,
floor 1 m, a 60-degree side from (1, 0) to (1.5774, 1)) with a branching coral rooted on the floor
between x = 0.4 and 0.6 m, about 0.59 m high; its top edge at y = 1 m. The paper's text gives no
water depth for this tank; BIPI2D packs the whole loop, so the water here fills it to its top edge,
H = 1 m (the free surface; the coral is submerged). That loop is the packing domain; for the run the
left wall and the inclined side are extended along their own lines up to TANK_TOP = 1.5 m and closed
there, as in ``reproductions/bipi-wedge-bisph/run.py`` (``outliers`` records whether a particle got
that far).

Starts (``lib.bipi_sph.make_start`` on the Step-1 fill ``initial_fill``): ``cartesian`` (Step 1
only) and ``bipi`` (BIPIPacker with the 1 % rules). ``--fig18 N ...`` adds ``bipi_fixed_N_M``
starts, exactly N Step-2a and M Step-2c iterations, M = the 1 %-rule start's Step-2c count read from
``results/summary.json`` (the paper's Fig. 16-18 study varies Step 2a and keeps Step 2c at about the
1 %-rule count); with ``--fig18`` only those starts run.

Run: :func:`ase_sphrelax.flows.scene.tank` (BISPH, BIPI Eqs. 16-21, rho0 1000, g 9.81,
mu 10 Pa s as the paper's coral runs, Wendland C2 with h_B = 2 dx, c0 = 10 sqrt(2 g H),
hydrostatic densities at t = 0), the same settings as bipi-wedge-bisph.

Measures, declared before the runs (issue 29 item 2):

* ``ke_mean``: KE (J/m) averaged over the whole run (trapezoid rule over the records); the measure is
  ``ke_mean_ratio_cartesian_over_bipi``, the goal ``>= 10``;
* ``pressure_error_final``: RMS of ``p - rho0 g (H - y)`` over the particles at the end, over
  ``rho0 g H``; and ``pressure_vs_depth``: the final pressure averaged in 10 depth bins against
  ``rho0 g d`` at the bins' mean depth.

``--wall-band 0`` switches Eq. 21's compressed density off (the controlled experiment, as in
bipi-wedge-bisph). Writes ``summary{tag}.json`` and ``ke{tag}.json.gz`` (KE(t) and the pressure
error of each start). ``--plot`` draws ``ke.png`` from ``ke.json.gz``, ``ke_band0`` and ``ke_fig18``
and writes ``window.json``: each run's KE averaged over the first WINDOW = 0.5 s (trapezoid rule),
so the shorter runs (Eq. 21 off, Fig. 18) compare with the first 0.5 s of the main ones, and the
Cartesian/BIPI ratios over that window. ``--plot pointwise`` does the same for the runs with the
default (pointwise) Eq. 21: ``ke_pw``, ``ke_band0`` (Eq. 21 off reads the same either way) and
``ke_fig18_pw``, into ``ke_pointwise.png`` and ``window_pointwise.json``.
"""
from __future__ import annotations

import argparse
import gzip
import json
import math
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from lib.bipi_sph import G, H_OVER_DX, RHO0, add_bisph_options, add_start_ratios, make_start  # noqa: E402
from lib.results_io import MergedRuns  # noqa: E402

HERE = Path(__file__).resolve().parent
EDGES = HERE / "coral_tank.edges"
DEPTH = 1.0  # the loop's top edge: BIPI2D fills the whole loop
MU = 10.0
TANK_TOP = 1.5
GOAL = 10.0  # issue 29: Cartesian / BIPI run-averaged KE
WINDOW = 0.5  # s: the common window of the main, Eq.-21-off and Fig. 18 runs
PLOTTED = {"segment": ("", "_band0", "_fig18"),  # the ke{tag}.json.gz that --plot READING draws and windows
           "pointwise": ("_pw", "_band0", "_fig18_pw")}
PLOT_FILES = {"segment": ("ke.png", "window.json"), "pointwise": ("ke_pointwise.png", "window_pointwise.json")}


def water():
    """The packing domain: the converted loop (its top edge is the free surface)."""
    from ase_sphrelax.boundary import BoundarySegments

    return BoundarySegments.from_edges(EDGES)


def tank_walls():
    """The run's walls: the loop with its two top corners moved up their walls' lines to TANK_TOP."""
    from ase_sphrelax.boundary import BoundarySegments
    from ase_sphrelax.domains.loops import read_edges

    (v,) = read_edges(EDGES, None)
    v = np.array(v, dtype=float)
    top = np.nonzero(np.isclose(v[:, 1], DEPTH))[0]
    assert len(top) == 2, "the converted loop has two vertices at the water surface"
    n = len(v)
    for k in top:
        below = v[(k - 1) % n] if not np.isclose(v[(k - 1) % n, 1], DEPTH) else v[(k + 1) % n]
        v[k] = below + (v[k] - below) * (TANK_TOP - below[1]) / (v[k, 1] - below[1])
    return BoundarySegments.from_vertices(v)


def pressure_vs_depth(sim, bins=10):
    """Final pressure averaged in depth bins against rho0 g d (both in Pa), with the bins' counts."""
    d = DEPTH - sim.r[:, 1]
    p = sim.pressure()
    edges = np.linspace(0.0, DEPTH, bins + 1)
    k = np.clip(np.digitize(d, edges) - 1, 0, bins - 1)
    out = dict(depth=[], p=[], p_hydrostatic=[], n=[])
    for b in range(bins):
        m = k == b
        if m.any():
            out["depth"].append(float(d[m].mean()))
            out["p"].append(float(p[m].mean()))
            out["p_hydrostatic"].append(float(RHO0 * G * d[m].mean()))
            out["n"].append(int(m.sum()))
    return out


def outliers(sim, walls, dx):
    """Where the final pressure error sits: particles outside the run's walls, those off rho0 g (H - y) by
    more than half of rho0 g H, the largest error (over rho0 g H) and its particle's distance to a wall (dx)."""
    from ase_sphrelax.flows.scene import wall_distance

    r = sim.r[:, :2]
    err = np.abs(sim.pressure() - RHO0 * G * (DEPTH - r[:, 1])) / (RHO0 * G * DEPTH)
    worst = int(np.argmax(err))
    return dict(n_escaped_final=int((walls.domain.phi(r) >= 0).sum()), n_pressure_off_half_final=int((err > 0.5).sum()),
                pressure_error_max_final=float(err[worst]), worst_xy=[float(c) for c in r[worst]],
                worst_wall_distance_dx=float(wall_distance(r[worst:worst + 1], walls)[0] / dx))


def plot(out, reading="segment"):
    """``ke.png`` (``ke_pointwise.png``): KE(t) on a log scale of the PLOTTED runs of one Eq. 21 reading in
    ``out``; Fig. 18's runs on the right."""
    from lib.bipi_figures import _plt, _save

    plt = _plt()
    window = {}
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8), sharey=True)
    main_tag, band0_tag, fig18_tag = PLOTTED[reading]
    for tag in PLOTTED[reading]:
        path = out / f"ke{tag}.json.gz"
        if not path.exists():
            continue
        with gzip.open(path, "rt") as f:
            curves = json.load(f)
        for name, c in curves.items():
            t, ke = np.asarray(c["t"]), np.maximum(np.asarray(c["ke"]), 1e-6)
            w = t <= WINDOW + 1e-9
            window[f"{name}{tag}"] = float(np.trapezoid(np.asarray(c["ke"])[w], t[w]) / (t[w][-1] - t[w][0]))
            label = f"{name}{' (Eq. 21 off)' if tag == band0_tag else ''}"
            if tag == fig18_tag:
                axes[1].semilogy(t, ke, lw=1, label=f"BIPI, {name.split('_')[2]} Step-2a iterations")
                continue
            axes[0].semilogy(t, ke, lw=1, ls="--" if tag != main_tag else "-", label=label)
            if tag == main_tag:
                keep = t <= (WINDOW if reading == "segment" else np.inf) + 1e-9
                axes[1].semilogy(t[keep], ke[keep], lw=1, color="k" if name == "cartesian" else "grey",
                                 label=f"{name} (1 % rules)" if name == "bipi" else name)
    axes[0].set(xlabel="t (s)", ylabel="KE (J/m)", title=f"coral tank, BISPH (Eq. 21 {reading}), dx = 0.02 m")
    axes[1].set(xlabel="t (s)", title="Fig. 18: Step-2a iterations")
    axes[0].set_ylim(1e-5, None)  # KE(0) = 0 is drawn at the clip
    for ax in axes:
        ax.legend(fontsize=7)
    fig.tight_layout()
    figure, window_file = PLOT_FILES[reading]
    _save(fig, out / figure)
    ratios = {f"cartesian_over_bipi{tag}": window[f"cartesian{tag}"] / window[f"bipi{tag}"]
              for tag in (main_tag, band0_tag) if f"cartesian{tag}" in window and f"bipi{tag}" in window}
    (out / window_file).write_text(json.dumps(dict(window_s=WINDOW, ke_mean=window, ratios=ratios), indent=1) + "\n")


def main(argv=None):
    from ase_sphrelax.drivers.bipi_packer import initial_fill
    from ase_sphrelax.flows.scene import tank, wall_distance

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=str(HERE / "results"))
    parser.add_argument("--dx", type=float, default=0.02)
    parser.add_argument("--t-end", type=float, default=2.0)
    parser.add_argument("--fig18", type=int, nargs="*", default=None,
                        help="Step-2a counts of fixed-iteration BIPI starts (Fig. 18); only these run")
    parser.add_argument("--wall-band", type=float, default=0.5,
                        help="Eq. 21's band in dx (0: compressed density off; the controlled experiment)")
    parser.add_argument("--plot", nargs="?", const="segment", choices=sorted(PLOTTED),
                        help="only draw ke.png (segment, the earlier runs) or ke_pointwise.png from the results in --out")
    add_bisph_options(parser)
    parser.add_argument("--tag", default="", help="suffix of summary{tag}.json and ke{tag}.json.gz")
    args = parser.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if args.plot:
        return plot(out, args.plot)
    if args.fig18:
        n2c = json.loads((out / "summary.json").read_text())["runs"]["bipi"]["iterations_2c"]
        names = [f"bipi_fixed_{n}_{n2c}" for n in args.fig18]
    else:
        names = ["cartesian", "bipi"] if args.start is None else [args.start]
    region, walls = water(), tank_walls()
    fill = initial_fill(region, args.dx)
    scale = RHO0 * G * DEPTH
    summary = dict(wall_band_dx=args.wall_band, eq21=args.eq21, segment_ratio=args.segment_ratio, dx=args.dx, h_support=H_OVER_DX * args.dx,
                   h_b=H_OVER_DX * args.dx / 2, t_end=args.t_end, depth=DEPTH, tank_top=TANK_TOP, mu=MU,
                   c0=10.0 * math.sqrt(2.0 * G * DEPTH), goal=GOAL, runs={})
    curves = {}
    for name in names:
        atoms, info = make_start(name, region, args.dx, H_OVER_DX * args.dx, fill)
        r = atoms.positions[:, :2]
        gap = wall_distance(r, region) / args.dx
        info = dict(info, wall_distance_min_dx=float(gap.min()), n_within_half_dx=int((gap < 0.5).sum()))
        print(f"start {name}: {len(r)} particles {info}", flush=True)
        sim = tank(walls, r, args.dx, DEPTH, g=G, mu=MU, rho0=RHO0, wall_band=args.wall_band,
                   eq21=args.eq21, segment_ratio=args.segment_ratio)
        t = time.perf_counter()
        hist = sim.run(args.t_end, record_every=args.t_end / 200, progress=False)
        wall_s = round(time.perf_counter() - t, 1)
        summary["runs"][name] = dict(info, n=len(r), steps=hist.steps, run_wall_time_s=wall_s,
                                     ke_mean=hist.mean_ke(), ke_final=hist.ke[-1],
                                     pressure_error_final=hist.pressure_error[-1] / scale,
                                     pressure_vs_depth=pressure_vs_depth(sim), **outliers(sim, walls, args.dx))
        curves[name] = dict(t=hist.t, ke=hist.ke, pressure_error=hist.pressure_error)
        print(f"  {name}: ke_mean {hist.mean_ke():.3g} ke_final {hist.ke[-1]:.3g} "
              f"p_err {hist.pressure_error[-1] / scale:.3g} wall {wall_s} s", flush=True)
    with MergedRuns(out, args.tag, summary, curves, merge=args.start is not None) as (summary, curves):
        if add_start_ratios(summary):
            summary["goal_met"] = summary["ke_mean_ratio_cartesian_over_bipi"] >= GOAL
    print(json.dumps({k: v for k, v in summary.items() if k != "runs"}, indent=1))


if __name__ == "__main__":
    main()
