"""A relaxation end to end against LAMMPS doing the FIRE minimisation (issue 9, item 6).

Scenes (h = 2.6 dx):

* ``periodic``: 316 x 316 periodic jittered square lattice (N = 99856, jitter 0.25 dx, dx = 1);
* ``circle``: Fan's default circle (centre (0.5, 0.5), r = 0.2) with dx scaled so that it
  holds about 1e5 particles (dx = 0.2 sqrt(pi / 1e5)), jitter 0.1 dx, seed 0.

For each scene and thread count, in ``--repeats`` interleaved rounds:

1. LAMMPS: ``lammps_io.run(atoms, h, dx, domain, steps=--steps, style="table", nthreads=T)``
   (data file and deck written, ``min_style fire``, the dump read back; the bounded circle's
   wall term through ``fix external``), end to end; its final Fan energy E_L;
2. ours: from the same Atoms, a FanCalculator and an ASE optimiser from ``make_optimizer``
   (numba threads T), run until E <= E_L (at most 10 x --steps steps), end to end:

   * ``lbfgs``: ``make_optimizer("lbfgs")``, our default quasi-Newton;
   * ``fire-lammps``: ASE's FIRE with LAMMPS's FIRE parameters (the deck's time step
     :func:`lammps_io.relaxation.default_timestep`, dtmax 10 dt, dmax 0.1 per atom (ASE caps
     the norm of the whole step: 0.1 sqrt(N)), Nmin 20, alpha 0.25, f_alpha 0.99, f_inc 1.1,
     f_dec 0.5): the same FIRE minimisation;
   * ``fire``: ``make_optimizer("fire")`` (not in the default set: its ``maxstep = 10 c h``
     caps the norm of the whole 3N step in ASE's FIRE, i.e. 10 c h / sqrt(N) per atom at
     N = 1e5, and it needed 1522 steps where LAMMPS's FIRE needed 200).

Reported: medians of the wall times, our time / LAMMPS time (target <= 1: "ours no
slower"), the steps each needed and the load average.

    python benchmarks/bench_relax_lammps.py [--steps 200] [--repeats 5] [--threads 1,2]

Writes ``benchmarks/results/relax_lammps.json``.
"""
from __future__ import annotations

import argparse
import math
import os
import statistics
import time
from pathlib import Path

import numba

import lammps_io
from lammps_io.relaxation import default_timestep
from ase_sphrelax import FanCalculator
from ase_sphrelax.build import fill, periodic_box
from ase_sphrelax.domains import Circle
from ase_sphrelax.drivers import make_optimizer

try:
    from _provenance import git_version, write_json
except ImportError:
    from benchmarks._provenance import git_version, write_json

RATIO = 2.6


def scenes():
    dx_c = 0.2 * math.sqrt(math.pi / 1e5)
    circle = Circle((0.5, 0.5), 0.2)
    return {
        "periodic": (None, 1.0, periodic_box((316, 316), dx=1.0, dim=2, lattice="square", jitter=0.25, seed=0)),
        "circle": (circle, dx_c, fill(circle, dx_c, jitter=0.1, seed=0)),
    }


def run_lammps(atoms, domain, dx, steps, threads):
    t0 = time.perf_counter()
    relaxed = lammps_io.run(atoms, RATIO * dx, dx, domain=domain, steps=steps, style="table", nthreads=threads)
    wall = time.perf_counter() - t0
    info = relaxed.info["lammps"]
    return wall, float(info["energy"]), int(info["iterations"])


def run_ours(atoms0, domain, dx, name, target, max_steps):
    t0 = time.perf_counter()
    atoms = atoms0.copy()
    atoms.calc = FanCalculator(h=RATIO * dx, dx=dx, domain=domain, dim=2)
    if name == "fire-lammps":  # LAMMPS's min_style fire defaults (min_modify), its deck's time step
        dt = default_timestep(RATIO * dx, dx**2, 2)
        # ASE caps the norm of the whole 3N step, LAMMPS's dmax each atom's: 0.1 sqrt(N) is the
        # cap of every atom moving 0.1
        opt = make_optimizer("fire", atoms, dt=dt, dtmax=10 * dt, maxstep=0.1 * math.sqrt(len(atoms)), Nmin=20,
                             a=0.25, astart=0.25, fa=0.99, finc=1.1, fdec=0.5)
    else:
        opt = make_optimizer(name, atoms)
    energy = atoms.get_potential_energy()
    for _ in opt.irun(fmax=0.0, steps=max_steps):
        energy = atoms.get_potential_energy()
        if energy <= target:
            break
    wall = time.perf_counter() - t0
    return wall, energy, opt.nsteps, energy <= target


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--steps", type=int, default=200, help="LAMMPS FIRE steps (its final E is the target)")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--threads", default="1,2")
    parser.add_argument("--optimizers", default="lbfgs,fire-lammps", help="lbfgs, fire-lammps, fire")
    parser.add_argument("--scenes", default="periodic,circle")
    parser.add_argument("--out", default=str(Path(__file__).parent / "results" / "relax_lammps.json"))
    args = parser.parse_args(argv)
    all_scenes = scenes()
    names = args.optimizers.split(",")
    # compile / load outside the timings
    small = periodic_box((20, 20), dx=1.0, dim=2, jitter=0.25, seed=0)
    run_ours(small, None, 1.0, "fire", -math.inf, 3)
    run_lammps(small, None, 1.0, 3, 1)
    rows = []
    print(f"load average {os.getloadavg()}", flush=True)
    for label in args.scenes.split(","):
        domain, dx, atoms = all_scenes[label]
        for threads in [int(t) for t in args.threads.split(",")]:
            numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
            load_before = os.getloadavg()
            lmp, ours = [], {n: [] for n in names}
            for _ in range(args.repeats):
                wall, e_l, iters = run_lammps(atoms, domain, dx, args.steps, threads)
                lmp.append(dict(wall=wall, energy=e_l, iterations=iters))
                for name in names:
                    w, e, s, reached = run_ours(atoms, domain, dx, name, e_l, 10 * args.steps)
                    ours[name].append(dict(wall=w, energy=e, steps=s, reached=reached))
            t_l = statistics.median(r["wall"] for r in lmp)
            row = dict(scene=label, n=len(atoms), dx=dx, threads=threads, lammps_steps=args.steps,
                       lammps=dict(wall=t_l, energy=statistics.median(r["energy"] for r in lmp),
                                   iterations=statistics.median(r["iterations"] for r in lmp), all=lmp),
                       ours={}, load_before=load_before, load_after=os.getloadavg())
            line = (f"{label} N={len(atoms)} threads={threads}: LAMMPS FIRE {args.steps} steps "
                    f"{t_l:.2f} s -> E {row['lammps']['energy']:.6e}")
            for name in names:
                t_o = statistics.median(r["wall"] for r in ours[name])
                row["ours"][name] = dict(wall=t_o, ratio=t_o / t_l, steps=statistics.median(r["steps"] for r in ours[name]),
                                         reached=all(r["reached"] for r in ours[name]), all=ours[name])
                line += (f" | ours {name} {t_o:.2f} s ({row['ours'][name]['steps']:.0f} steps, "
                         f"reached {row['ours'][name]['reached']}) ratio {t_o / t_l:.2f}")
            print(line + f" | load {load_before[0]:.2f} -> {row['load_after'][0]:.2f}", flush=True)
            rows.append(row)
    result = dict(version=git_version(), started=time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
                  repeats=args.repeats, rows=rows, load_average_end=os.getloadavg())
    write_json(args.out, result)
    return result


if __name__ == "__main__":
    main()
