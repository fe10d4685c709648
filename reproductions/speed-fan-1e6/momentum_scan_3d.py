"""Fewer steps are not a shorter run: heavy-ball momentum against ``make_optimizer("fire")`` on Fan's sphere (the 3D
scene, measure and target of ``benchmarks/bench_fan_1e6.py``), counting steps *and* neighbour-list builds.

The question, declared before the runs: does a first-order method that takes fewer steps than FIRE to the target
also take fewer list builds, the largest part of a 3D step's time at 1e6 (``results/profile_3d_2t.json``)?

Heavy ball (Polyak): ``x_{k+1} = x_k + alpha F_k + beta (x_k - x_{k-1})``, the momentum dropped for a step whose
move points against the forces (``F_k . dx < 0``, summed over all particles). ``alpha`` is given in units of
``dt0^2 = 0.01 h / max|F_0|``, FIRE's first step from ``make_optimizer`` (so ``alpha = 20 dt0^2`` is FIRE's
``dt = 4.5 dt0``; FIRE's own ``dtmax`` is 2.5 dt0). The largest eigenvalue ``lambda`` of the energy's Hessian at
the start (20 power iterations on central-difference Hessian-vector products) gives heavy ball's stability edge
``2 (1 + beta) / lambda``, stored in the same units.

    NUMBA_NUM_THREADS=2 python reproductions/speed-fan-1e6/momentum_scan_3d.py --sizes 1e4,1e5 --timed 1e6 \
        --out reproductions/speed-fan-1e6/results/momentum_scan_3d.json

A second question, declared before its runs (``--cut 0.005``): with FIRE's cut of each particle's move in one step
(``max_particle_step``, 0.005 h in 3D, which took FIRE from 46 list builds to 16 at 1e6), does heavy ball keep its
fewer steps, and does it then build the list as seldom as FIRE? Each particle's move is cut to ``cut * h`` after the
momentum is added; the momentum of the next step is the move made. FIRE's rows are ``make_optimizer("fire")``'s,
which cuts at 0.005 h in 3D by default.

    NUMBA_NUM_THREADS=2 python reproductions/speed-fan-1e6/momentum_scan_3d.py --sizes 1e5 --grid 20:0.85,22:0.85 \
        --cut 0.005 --timed 1e6 --out reproductions/speed-fan-1e6/results/momentum_cut_3d.json

The timed 1e6 run does its vector work in numpy (``update_time``, stored apart) and checks the measure every step
from the step's forces, as the bench does; the FIRE run it is read against is the bench's own
(``benchmarks/results/bench_fan_1e6.json``, 3D). Step and build counts do not depend on the load; the time does.
"""
import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))

GRID = [(16.0, 0.85), (20.0, 0.8), (20.0, 0.85), (20.0, 0.9), (22.0, 0.85), (25.0, 0.85)]
TARGET = 6e-4


def start(n):
    """The bench's 3D start with Fan's calculator: ``(domain, dx, h, atoms)``."""
    import bench_fan_1e6 as bf

    from ase_sphrelax import FanCalculator

    domain, dx, atoms = bf.scene(3, n)
    h = bf.RATIO * dx
    atoms.calc = FanCalculator(h=h, dx=dx, domain=domain)
    return domain, dx, h, atoms


def measure(atoms, f_pc, domain, h, dx):
    """The bench's measure from a step's forces: the interior mean ``h |F| / (2 v0)``."""
    import bench_fan_1e6 as bf

    return h / (2.0 * dx**3) * bf.interior_mean_norm(f_pc, domain.phi(atoms.positions), -h)


def dt0_squared(atoms, h):
    f_pc = atoms.get_forces()
    return 0.01 * h / float(np.sqrt((f_pc**2).sum(axis=1)).max())


def heavy_ball(n, alpha_dt0, beta, max_steps=400, cut_over_h=None):
    """Steps and list builds to the target (steps None if not reached), and the time of the vector work;
    ``cut_over_h``: each particle's move cut to this many h."""
    domain, dx, h, atoms = start(n)
    t0 = time.perf_counter()
    alpha = alpha_dt0 * dt0_squared(atoms, h)
    f_pc = atoms.get_forces()
    x_pc = atoms.positions.copy()
    prev_pc = x_pc.copy()
    d_pc = np.empty_like(x_pc)
    update = 0.0
    m = None
    for step in range(1, max_steps + 1):
        t1 = time.perf_counter()
        np.subtract(x_pc, prev_pc, out=d_pc)
        d_pc *= beta
        d_pc += alpha * f_pc
        if np.vdot(f_pc, d_pc) < 0:  # the move points against the forces: drop the momentum
            np.multiply(f_pc, alpha, out=d_pc)
        if cut_over_h is not None:
            length_p = np.sqrt((d_pc * d_pc).sum(axis=1))
            far = length_p > cut_over_h * h
            d_pc[far] *= (cut_over_h * h / length_p[far])[:, None]
        prev_pc, x_pc = x_pc, prev_pc
        np.add(prev_pc, d_pc, out=x_pc)
        atoms.positions[:] = x_pc
        update += time.perf_counter() - t1
        f_pc = atoms.get_forces()
        m = measure(atoms, f_pc, domain, h, dx)
        if not np.isfinite(m) or m > 1.0:  # diverged
            return dict(steps=None, diverged=True, measure=None, builds=int(atoms.calc.nlist.builds))
        if m <= TARGET:
            return dict(steps=step, diverged=False, measure=m, builds=int(atoms.calc.nlist.builds),
                        wall_time=time.perf_counter() - t0, update_time=update)
    return dict(steps=None, diverged=False, measure=m, builds=int(atoms.calc.nlist.builds))


def fire(n, max_steps=400):
    """``make_optimizer("fire")``'s steps and list builds to the target."""
    from ase_sphrelax import make_optimizer

    domain, dx, h, atoms = start(n)
    opt = make_optimizer("fire", atoms)
    for _ in opt.irun(fmax=0.0, steps=max_steps):
        m = measure(atoms, atoms.calc.results["forces"], domain, h, dx)
        if m <= TARGET:
            return dict(steps=int(opt.nsteps), measure=m, builds=int(atoms.calc.nlist.builds))
    return dict(steps=None, measure=m, builds=int(atoms.calc.nlist.builds))


def largest_eigenvalue(n, iterations=20):
    """The Hessian's largest eigenvalue at the start in units of ``1 / dt0^2`` (power iteration)."""
    domain, dx, h, atoms = start(n)
    x0_pc = atoms.positions.copy()
    scale = dt0_squared(atoms, h)
    v_pc = np.random.default_rng(1).normal(size=x0_pc.shape)
    v_pc /= np.linalg.norm(v_pc)
    eps = 1e-6 * dx
    lam = None
    for _ in range(iterations):
        atoms.positions = x0_pc + eps * v_pc
        f_plus = atoms.get_forces().copy()
        atoms.positions = x0_pc - eps * v_pc
        hv_pc = (atoms.get_forces() - f_plus) / (2.0 * eps)
        lam = float(np.vdot(v_pc, hv_pc))
        v_pc = hv_pc / np.linalg.norm(hv_pc)
    return lam * scale


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--sizes", default="1e4,1e5")
    parser.add_argument("--timed", type=float, default=None, help="one heavy-ball run at this size, timed")
    parser.add_argument("--grid", default=None, help="alpha:beta pairs, comma separated (default: the scan's grid)")
    parser.add_argument("--cut", type=float, default=None, help="each particle's move cut to this many h")
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args(argv)
    import numba

    import bench_fan_1e6 as bf

    grid = GRID if args.grid is None else [tuple(float(v) for v in pair.split(":")) for pair in args.grid.split(",")]
    rows = []
    for n in [float(s) for s in args.sizes.split(",")]:
        lam = largest_eigenvalue(n)
        row = dict(n=n, lambda_dt0=lam, fire=fire(n), heavy_ball=[])
        for alpha, beta in grid:
            run = heavy_ball(n, alpha, beta, cut_over_h=args.cut)
            run.update(alpha_dt0=alpha, beta=beta, edge_dt0=2.0 * (1.0 + beta) / lam, cut_over_h=args.cut)
            run.pop("wall_time", None), run.pop("update_time", None)  # not timed at these sizes
            row["heavy_ball"].append(run)
            print(json.dumps(dict(n=n, **run)), flush=True)
        print(json.dumps(dict(n=n, fire=row["fire"], lambda_dt0=lam)), flush=True)
        rows.append(row)
    record = dict(target=TARGET, threads=numba.get_num_threads(), rows=rows, cut_over_h=args.cut)
    if args.timed:
        bf.warm_up(3)
        record["load_average_before_timed"] = list(os.getloadavg())
        alpha, beta = grid[0] if args.grid else (20.0, 0.85)
        timed = heavy_ball(args.timed, alpha, beta, cut_over_h=args.cut)
        timed.update(n=args.timed, alpha_dt0=alpha, beta=beta, cut_over_h=args.cut)
        record["timed"] = timed
        print(json.dumps(dict(timed=timed)), flush=True)
    record["version"] = subprocess.run(["git", "describe", "--always", "--dirty"], capture_output=True, text=True,
                                       cwd=ROOT).stdout.strip()
    record["command"] = ("NUMBA_NUM_THREADS=2 python reproductions/speed-fan-1e6/momentum_scan_3d.py "
                         + " ".join(argv if argv is not None else sys.argv[1:]))
    args.out.write_text(json.dumps(record, indent=1) + "\n")


if __name__ == "__main__":
    main()
