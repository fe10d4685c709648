"""Issue 29 item 4: which start is calmest, per downstream wall model, measured with ``ase_sphrelax.settle``.

    python reproductions/bipi-settle-guidance/run.py --out reproductions/bipi-settle-guidance/results [--dx 0.02] [--t-end 0.5] [--tag T]

The wedge tank of ``reproductions/lib/bipi_sph.py`` (2.05 m wide, a symmetric 90-degree wedge sqrt(2)/8 m
high, 0.5 m of water) at dx = 0.02 m (``--dx``). Three starts of the same Step-1 fill (``lib.bipi_sph.make_start``):
``cartesian`` (Step 1), ``bipi`` (BIPIPacker, 1 % rules), ``fan`` (2000 steps of Fan's Eq. 2.4 with the default boundary term). Each is run
at rest by :func:`ase_sphrelax.settle` (support h = 4 dx) under three wall models:

* ``boundary integrals``: ``solver="bisph"`` (BIPI Eqs. 16-21, mu = 10 Pa s; what ``sphrelax settle
  --solver bisph`` runs);
* ``grid wall particles``: ``solver="lammps"`` with ceil(h/dx) layers of the Step-1 grid outside the walls
  (``add_walls``, as ``sphrelax pack --walls``), alpha = 0.5;
* ``packed wall particles``: ``solver="lammps"`` with one BIPI packing of the wall band
  (``packed_wall_particles``, as ``sphrelax pack --walls --wall-mode packed``), the same for every start.

Writes ``summary{tag}.json`` (per wall model and start: run-averaged, final and largest KE, pressure error,
largest drop, particle counts, ``stable`` as ``settle`` judges it; the calmest start (stable runs first, then
by run-averaged KE), its margin over the next stable start, and the stable starts' KE over the calmest's) and ``ke{tag}.json.gz``
(KE(t) of every run), and ``ke{tag}.png`` (KE(t), log scale, one panel per wall model).
"""
from __future__ import annotations

import argparse
import gzip
import json
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from lib.bipi_sph import DEPTH, G, H_OVER_DX, RHO0, make_start, packed_walls, wedge_tank, with_walls  # noqa: E402

STARTS = ("cartesian", "bipi", "fan")
#: the recipe of each start in lib.bipi_sph.make_start: Fan with the package's default wall term, what a user gets
START_RECIPES = {"cartesian": "cartesian", "bipi": "bipi", "fan": "fan_default"}
MODELS = {  # name: (solver, walls)
    "boundary integrals": ("bisph", None),
    "grid wall particles": ("lammps", "grid"),
    "packed wall particles": ("lammps", "packed"),
}
COMMANDS = {
    "boundary integrals": "sphrelax settle IN.extxyz --boundary FILE --dx DX --solver bisph --t-end T",
    "grid wall particles": "sphrelax pack ... --walls; sphrelax settle packed.extxyz --boundary FILE --dx DX "
                           "--solver lammps --t-end T",
    "packed wall particles": "sphrelax pack ... --walls --wall-mode packed; sphrelax settle packed.extxyz "
                             "--boundary FILE --dx DX --solver lammps --t-end T",
}


def plot(curves, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from ase_sphrelax.plotting import save_figure

    fig, axes = plt.subplots(1, len(curves), figsize=(4 * len(curves), 3.2), sharey=True)
    for ax, (model, runs) in zip(np.atleast_1d(axes), curves.items()):
        for name, ke in runs.items():
            t, k = np.asarray(ke).T
            ax.semilogy(t, np.maximum(k, 1e-12), label=name)
        ax.set_title(model)
        ax.set_xlabel("t (s)")
    np.atleast_1d(axes)[0].set_ylabel("KE (J/m)")
    np.atleast_1d(axes)[0].legend()
    fig.tight_layout()
    save_figure(fig, path, dpi=80)


def main(argv=None):
    from ase_sphrelax import settle
    from ase_sphrelax.drivers.bipi_packer import initial_fill

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="reproductions/bipi-settle-guidance/results")
    parser.add_argument("--dx", type=float, default=0.02)
    parser.add_argument("--t-end", type=float, default=0.5)
    parser.add_argument("--models", nargs="+", choices=tuple(MODELS), default=tuple(MODELS),
                        help="the downstream wall models to run (default all three)")
    parser.add_argument("--tag", default="", help="suffix of summary{tag}.json, ke{tag}.json.gz, ke{tag}.png")
    args = parser.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    dx, h = args.dx, H_OVER_DX * args.dx
    water = wedge_tank()
    fill = initial_fill(water, dx)
    starts = {}
    for name in STARTS:
        atoms, info = make_start(START_RECIPES[name], water, dx, h, fill)
        starts[name] = (atoms, {k: v for k, v in info.items() if k != "reason"})
        print(f"start {name}: {len(atoms)} particles {starts[name][1]}", flush=True)
    if "packed wall particles" in args.models:
        packed, packed_info = packed_walls(water, dx, h, DEPTH)
        print(f"packed walls: {packed_info['n']} in {packed_info['layers']} layers", flush=True)
    summary = dict(tank="wedge (reproductions/lib/bipi_sph.py)", dx=dx, h=h, t_end=args.t_end, rho0=RHO0, g=G,
                   starts={n: i for n, (_, i) in starts.items()}, models={})
    curves = {}
    for model in args.models:
        solver, walls = MODELS[model]
        rows, curves[model] = {}, {}
        for name, (atoms, _) in starts.items():
            run_atoms = atoms if walls is None else with_walls(atoms, water, dx, h, DEPTH,
                                                               walls=packed if walls == "packed" else None)
            t = time.perf_counter()
            rec = settle(run_atoms, water, dx, solver=solver, t_end=args.t_end, h=h, progress=False)
            rows[name] = dict(ke_mean=rec["ke_mean"], ke_final=rec["ke_final"], ke_max=rec["ke_max"],
                              pressure_error=rec["pressure_error"], max_drop=rec["max_drop"],
                              n_fluid=rec["n_fluid"], n_wall=rec.get("n_wall", 0), steps=rec["steps"],
                              t_reached=rec["ke_history"][-1][0], stable=rec["stable"],
                              stability_reason=rec["stability_reason"], wall_time_s=round(time.perf_counter() - t, 1))
            curves[model][name] = rec["ke_history"]
            print(f"{model} / {name}: {rows[name]}", flush=True)
        order = sorted(rows, key=lambda n: (not rows[n]["stable"], rows[n]["ke_mean"]))  # unstable runs last
        stable = [n for n in order if rows[n]["stable"]]
        best = order[0]
        margin = rows[stable[1]]["ke_mean"] / rows[best]["ke_mean"] if len(stable) > 1 and best == stable[0] else None
        summary["models"][model] = dict(
            solver=solver, walls=walls, command=COMMANDS[model], runs=rows, calmest=best, stable=stable,
            margin=margin, ratio_over_calmest={n: rows[n]["ke_mean"] / rows[best]["ke_mean"] for n in stable})
        print(f"{model}: calmest {best}, over the next stable start: {margin}; stable: {stable}", flush=True)
    (out / f"summary{args.tag}.json").write_text(json.dumps(summary, indent=1) + "\n")
    with gzip.open(out / f"ke{args.tag}.json.gz", "wt") as f:
        json.dump(curves, f)
    plot(curves, out / f"ke{args.tag}.png")
    print(json.dumps({m: (v["calmest"], v["margin"], v["stable"]) for m, v in summary["models"].items()}))


if __name__ == "__main__":
    main()
