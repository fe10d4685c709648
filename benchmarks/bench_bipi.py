"""BIPI packing speed: per-iteration time of Step 2a and Step 2c against N (the paper's Fig. 23).

The paper's Step 2c grows quadratically with N (a direct neighbour search); here both stages run on
the cell list and the particle-boundary query, so both must be linear. Systems: the trapezoid
(``../shared/geometries/TrapezoidalTank.edges``) filled by Step 1 at dx = sqrt(1.25 / N) for
N = 1e3 ... 1e5, h_B / dx_r = 2 (h = 4 dx), BIPI2D's segment refinement is not needed (exact
integrals; ``band_rule="ball"``).

For each N, in the same run:

* Step 2a: ``--warm`` untimed iterations (compilation, first list), then the median wall time of
  ``--iterations`` iterations; ``n_selected`` is the size of the sub-system it evaluates;
* Step 2c: the same, after Step 2b froze the boundary layer (all particles evaluated);
* at the largest N, FanCalculator's warm evaluation (energy and forces, Verlet list reused, the same
  particles, h and dx, the trapezoid as its level-set domain): best of ``--repeats``.

Goals (issue 7 item 6): fitted exponents of t(N) <= 1.15 for 2a and 2c; 2a proportional to the
selected particles (exponent of t(n_selected) <= 1.15, and t(2a)/t(2c) well below 1); one 2c
iteration at N ~ 1e5 at most 3x a FanCalculator warm evaluation.

    python benchmarks/bench_bipi.py            # N = 1e3, 3e3, 1e4, 3e4, 1e5
    python benchmarks/bench_bipi.py --quick    # N = 1e3, 3e3, 1e4

3D (issue 17 item 6: one Step-2c iteration at 1e5 at most 3 FanCalculator warm evaluations): the sphere of
radius 0.5 of ``reproductions/bipi-table/run.py`` (``Sphere.to_mesh(3)``, 1280 triangles) filled by Step 1 at
dx = (volume / N)^(1/3), h = 4 dx; Step 2c only (``--no-2a``), the Fan evaluation on the same particles with
the sphere as its domain:

    python benchmarks/bench_bipi.py --dim 3 --sizes 1e4 1e5 --no-2a --warm 2 --iterations 5 \
        --out benchmarks/results/bench_bipi_3d.json

Writes benchmarks/results/bench_bipi.json; prints the load average (2 vCPUs shared by the team:
compare only the ratios taken in one run).
"""
from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import sys
import time
import warnings
from pathlib import Path

import numba
import numpy as np
from ase.calculators.calculator import all_changes

from ase_sphrelax import BIPICalculator, BIPIPacker, FanCalculator
from ase_sphrelax.boundary import BoundarySegments, BoundaryTriangles
from ase_sphrelax.domains import Sphere
from ase_sphrelax.drivers.bipi_packer import initial_fill

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _provenance import git_version  # noqa: E402

GEOMETRY = Path(__file__).resolve().parents[2] / "shared" / "geometries" / "TrapezoidalTank.edges"
RESULTS = Path(__file__).resolve().parent / "results"
AREA = 1.25


def stage_times(atoms, calc, stages, warm, iterations):
    """Median wall and CPU time per iteration of the last ``iterations`` of a stage, and its sizes."""
    cap = warm + iterations
    packer = BIPIPacker(atoms, calc, stages=stages, max_steps_2a=cap, max_steps_2c=cap, window=10**9)
    wall, cpu = [], []
    w0, c0 = time.perf_counter(), time.process_time()
    for _ in packer.irun():
        w1, c1 = time.perf_counter(), time.process_time()
        if packer.history and packer.history[-1]["stage"] == stages[-1]:
            wall.append(w1 - w0)
            cpu.append(c1 - c0)
        w0, c0 = time.perf_counter(), time.process_time()
    last = packer.history[-1]
    return float(np.median(wall[warm:])), float(np.median(cpu[warm:])), last["n_selected"], last["n_pack"]


def fan_warm(atoms, h, dx, domain, repeats, dim=2):
    """Best wall and CPU time of a FanCalculator evaluation with its Verlet list reused."""
    calc = FanCalculator(h=h, dx=dx, domain=domain, boundary_term="level_set")  # as measured (issue 33)
    calc.calculate(atoms, ["energy", "forces"], all_changes)
    calc.calculate(atoms, ["energy", "forces"], all_changes)  # builds the Verlet list
    wall = cpu = np.inf
    rng = np.random.default_rng(0)
    for _ in range(repeats):
        moved = atoms.copy()
        moved.positions[:, :dim] += rng.uniform(-0.01 * dx, 0.01 * dx, (len(atoms), dim))
        w, c = time.perf_counter(), time.process_time()
        calc.calculate(moved, ["energy", "forces"], all_changes)
        wall, cpu = min(wall, time.perf_counter() - w), min(cpu, time.process_time() - c)
    assert calc.nlist.builds == 1
    return wall, cpu


def boundary(dim):
    """The benchmark's boundary and the size of its domain (area or volume)."""
    if dim == 2:
        return BoundarySegments.from_edges(GEOMETRY), AREA
    sphere = Sphere((0.0, 0.0, 0.0), 0.5)
    return BoundaryTriangles.from_domain(sphere.to_mesh(3)), 4.0 / 3.0 * np.pi * 0.5**3


def fit(x, y):
    return float(np.polyfit(np.log(x), np.log(y), 1)[0])


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", nargs="*", type=float, default=[1e3, 3e3, 1e4, 3e4, 1e5])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--warm", type=int, default=5)
    parser.add_argument("--iterations", type=int, default=15)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--out", default=str(RESULTS / "bench_bipi.json"))
    parser.add_argument("--dim", type=int, default=2, choices=[2, 3],
                        help="2: the trapezoid (default); 3: the sphere of reproductions/bipi-table/run.py")
    parser.add_argument("--no-2a", dest="step_2a", action="store_false", help="time Step 2c only")
    parser.add_argument("--threads", type=int, default=1,
                        help="numba threads (default 1: CPU time of one thread is robust on the shared machine)")
    args = parser.parse_args(argv)
    sizes = [1e3, 3e3, 1e4] if args.quick else args.sizes
    numba.set_num_threads(args.threads)
    warnings.simplefilter("ignore", FutureWarning)
    load_start = os.getloadavg()
    print(f"load average {load_start}, numba threads {numba.get_num_threads()}", flush=True)
    seg, size = boundary(args.dim)
    rows = []
    for n in sizes:
        dx = float((size / n) ** (1.0 / args.dim))
        atoms = initial_fill(seg, dx)
        calc = BIPICalculator.from_paper(2.0, dx, seg)
        if args.step_2a:
            w2a, c2a, n_sel, n_pack_2a = stage_times(atoms.copy(), calc, ("2a",), args.warm, args.iterations)
        else:
            w2a = c2a = None  # not timed (JSON null)
            n_sel = n_pack_2a = 0
        calc = BIPICalculator.from_paper(2.0, dx, seg)
        w2c, c2c, _, n_pack_2c = stage_times(atoms.copy(), calc, ("2b", "2c"), args.warm, args.iterations)
        row = dict(n_target=n, dx=dx, n=len(atoms), n_selected_2a=n_sel, n_packable_2a=n_pack_2a,
                   n_unfrozen_2c=n_pack_2c, wall_2a=w2a, cpu_2a=c2a, wall_2c=w2c, cpu_2c=c2c)
        stage_2a = (f"2a: {c2a * 1e3:8.2f} ms CPU ({w2a * 1e3:8.2f} wall, {n_sel} selected)  " if args.step_2a
                    else "")
        print(f"N={len(atoms):7d} dx={dx:.5f}  {stage_2a}2c: {c2c * 1e3:8.2f} ms CPU ({w2c * 1e3:8.2f} wall)", flush=True)
        rows.append(row)
    n = np.array([r["n"] for r in rows], float)
    out = dict(rows=rows, dim=args.dim, time="median CPU time per iteration (process_time), wall time beside it",
               exponent_2a_vs_n=fit(n, [r["cpu_2a"] for r in rows]) if args.step_2a else None,
               exponent_2a_vs_selected=(fit([r["n_selected_2a"] for r in rows], [r["cpu_2a"] for r in rows])
                                        if args.step_2a else None),
               exponent_2c_vs_n=fit(n, [r["cpu_2c"] for r in rows]) if len(rows) > 1 else None)
    big = rows[-1]
    atoms = initial_fill(seg, big["dx"])
    fan_wall, fan_cpu = fan_warm(atoms, 4 * big["dx"], big["dx"], seg.domain, args.repeats, args.dim)
    out.update(fan_warm_cpu=fan_cpu, fan_warm_wall=fan_wall, ratio_2c_over_fan_warm_cpu=big["cpu_2c"] / fan_cpu,
               ratio_2c_over_fan_warm_wall=big["wall_2c"] / fan_wall, load_average_start=load_start,
               load_average_end=os.getloadavg(), numba_threads=numba.get_num_threads(), git=git_version(),
               machine=platform.platform(), date=datetime.datetime.now().isoformat(timespec="seconds"))
    print(f"exponents (CPU): 2a vs N {out['exponent_2a_vs_n']}, 2a vs selected {out['exponent_2a_vs_selected']}, "
          f"2c vs N {out['exponent_2c_vs_n']}")
    print(f"N={big['n']}: 2c iteration {big['cpu_2c'] * 1e3:.2f} ms CPU, FanCalculator warm {fan_cpu * 1e3:.2f} ms CPU, "
          f"ratio {out['ratio_2c_over_fan_warm_cpu']:.2f} (wall ratio {out['ratio_2c_over_fan_warm_wall']:.2f}); "
          f"load average {os.getloadavg()}")
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
