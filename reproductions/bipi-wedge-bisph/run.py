"""BIPI Figs. 13-14 in BISPH: the wedge tank at rest from a Cartesian and a BIPI start, boundary-integral walls.

    python reproductions/bipi-wedge-bisph/run.py --out reproductions/bipi-wedge-bisph/results [--dx 0.02] [--t-end 1.5]

The tank of ``reproductions/lib/bipi_sph.py`` (2.05 m wide, a symmetric 90-degree wedge sqrt(2)/8 m
high on the floor, water 0.5 m deep). Both starts come from the same Step-1 fill
(``initial_fill``); ``bipi`` is then packed by ``BIPIPacker`` with the 1 % rules against the water
region (the free surface as its top edge, as BIPI2D packs). Each runs in
:class:`ase_sphrelax.flows.BISPH` (BIPI Eqs. 16-21: rho0 1000, g 9.81, mu 10 Pa s, Wendland C2 with
h_B = 2 dx, i.e. support 4 dx; Molteni-Colagrossi delta 0.1 with the hydrostatic part removed;
c0 = 10 sqrt(2 g H)), hydrostatic at t = 0, in the same tank walled up to 1 m (the walls above the
water are never reached). Records each start's smallest distance to a wall (in dx) and how many
particles start within dx/2 of one (inside Eq. 21's compressed-density band). Writes
``summary{tag}.json`` (run-averaged KE of each start, their ratio, the final KE and pressure error,
the packing's iterations) and ``ke{tag}.json.gz`` (KE(t) of each). ``--wall-band 0`` switches
Eq. 21 off (the controlled experiment); ``--viscosity pcg`` runs Fig. 14b's particle-consistent-gradient
viscous term.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
import warnings
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from lib.results_io import MergedRuns  # noqa: E402
from lib.bipi_sph import (DEPTH, G, H_OVER_DX, RHO0, WEDGE_HEIGHT, WIDTH, add_bisph_options,  # noqa: E402
                          add_start_ratios, wedge_tank)

MU = 10.0
TANK_TOP = 1.0


def tank_walls():
    """The wedge tank walled up to TANK_TOP (the run's walls: the free surface is free)."""
    from ase_sphrelax.boundary import BoundarySegments

    c, b = 0.5 * WIDTH, WEDGE_HEIGHT
    return BoundarySegments.from_vertices([[0.0, 0.0], [c - b, 0.0], [c, WEDGE_HEIGHT], [c + b, 0.0],
                                           [WIDTH, 0.0], [WIDTH, TANK_TOP], [0.0, TANK_TOP]])


def starts(dx, names=("cartesian", "bipi")):
    from ase_sphrelax import BIPICalculator
    from ase_sphrelax.drivers.bipi_packer import BIPIPacker, initial_fill

    water = wedge_tank()
    fill = initial_fill(water, dx)
    out = {"cartesian": (fill.positions.copy(), {})}
    if "bipi" not in names:
        return out
    atoms = fill.copy()
    t = time.perf_counter()
    packer = BIPIPacker(atoms, BIPICalculator(h=H_OVER_DX * dx, dx=dx, boundary=water))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        packer.run()
    s = packer.summary()
    out["bipi"] = (atoms.positions.copy(), dict(iterations_2a=s["iterations_2a"], iterations_2c=s["iterations_2c"],
                                                pack_wall_time_s=round(time.perf_counter() - t, 1)))
    return out


def main(argv=None):
    from ase_sphrelax.flows.scene import tank, wall_distance

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="reproductions/bipi-wedge-bisph/results")
    parser.add_argument("--dx", type=float, default=0.02)
    parser.add_argument("--t-end", type=float, default=1.5)
    parser.add_argument("--wall-band", type=float, default=0.5,
                        help="Eq. 21's band in dx (0: compressed density off; the controlled experiment)")
    parser.add_argument("--viscosity", choices=("boundary_layer", "pcg"), default="boundary_layer",
                        help="BISPH's viscous form: the boundary-layer form, or Fig. 14b's particle-consistent gradient")
    add_bisph_options(parser)
    parser.add_argument("--records", type=int, default=300, help="KE records over the run (default 300)")
    parser.add_argument("--tag", default="", help="suffix of summary{tag}.json and ke{tag}.json.gz")
    args = parser.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    walls = tank_walls()
    summary = dict(wall_band_dx=args.wall_band, eq21=args.eq21, segment_ratio=args.segment_ratio, dx=args.dx, h_support=H_OVER_DX * args.dx,
                   h_b=H_OVER_DX * args.dx / 2, t_end=args.t_end, mu=MU, viscosity=args.viscosity, c0=10.0 * math.sqrt(2.0 * G * DEPTH), runs={})
    curves = {}
    for name, (r, info) in starts(args.dx, ("cartesian", "bipi") if args.start is None else (args.start,)).items():
        if args.start not in (None, name):
            continue
        print(f"start {name}: {len(r)} particles {info}", flush=True)
        sim = tank(walls, r, args.dx, DEPTH, g=G, mu=MU, rho0=RHO0, wall_band=args.wall_band,
                   viscosity=args.viscosity, eq21=args.eq21, segment_ratio=args.segment_ratio)
        gap = wall_distance(r, walls) / args.dx
        info = dict(info, wall_distance_min_dx=float(gap.min()), n_within_half_dx=int((gap < 0.5).sum()))
        t = time.perf_counter()
        hist = sim.run(args.t_end, record_every=args.t_end / args.records)
        scale = RHO0 * G * DEPTH
        summary["runs"][name] = dict(info, n=len(r), steps=hist.steps,
                                     run_wall_time_s=round(time.perf_counter() - t, 1),
                                     ke_mean=hist.mean_ke(), ke_final=hist.ke[-1],
                                     pressure_error_final=hist.pressure_error[-1] / scale)
        curves[name] = dict(t=hist.t, ke=hist.ke, pressure_error=hist.pressure_error)
        print(f"  {summary['runs'][name]}", flush=True)
    with MergedRuns(out, args.tag, summary, curves, merge=args.start is not None) as (summary, curves):
        add_start_ratios(summary)
    print(json.dumps(summary, indent=1))


if __name__ == "__main__":
    main()
