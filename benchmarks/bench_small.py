"""Small systems: the per-step overhead of the Eq. 2.4 demo and the first step on a warm cache (issue 9, item 3).

The scene is `sphrelax relax`'s default: Fan's circle (centre (0.5, 0.5), r = 0.2,
dx = 1/256, h = 2.6 dx, 8224 particles, jitter 0.1, seed 0), Eq. 2.4 with c = 0.01.

* ``warm evaluation``: one FanCalculator energy+forces evaluation with the Verlet list
  reused (``calc.calculate`` after a move of 1e-4 dx);
* ``demo step``: one step of the demo's relaxation, as the CLI runs it
  (``make_optimizer("fan")`` with a tqdm progress observer, ``opt.run``), from the time of
  ``--steps`` steps (list rebuilds included, as in the demo);
* ``ratio``: demo step / warm evaluation (target <= 1.3), both medians of ``--repeats``
  interleaved rounds, in CPU time (``time.process_time``): 8224 particles run on one thread
  (below ``PARALLEL_MIN``), and on this shared machine wall time includes the time slices
  given to other processes (at a load of 9 a 200-step run's mean wall time per step was 7x
  its median evaluation while its CPU time was not); wall times are reported too;
* ``first step``: in a fresh process with a warm numba cache, the time from the start of
  the relaxation code (scene built, calculator attached) to the end of the first
  Eq. 2.4 step: numba's start-up and cache loads, the first evaluation, the step and the
  evaluation after it (target < 1 s); the imports (ase_sphrelax and ASE's optimisers, whose
  package imports scipy.optimize) are reported beside it.

    python benchmarks/bench_small.py [--steps 200] [--repeats 5]

Writes ``benchmarks/results/bench_small.json``.
"""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

try:
    from _provenance import git_version, write_json
except ImportError:
    from benchmarks._provenance import git_version, write_json

FIRST_STEP = r"""
import time
t0 = time.perf_counter()
from ase_sphrelax import FanCalculator
from ase_sphrelax.build import fill
from ase_sphrelax.domains import Circle
from ase_sphrelax.drivers import make_optimizer
import ase.optimize  # ASE's optimisers (their package imports scipy.optimize): an import, not the step
t1 = time.perf_counter()
domain, dx = Circle((0.5, 0.5), 0.2), 1 / 256
atoms = fill(domain, dx, jitter=0.1, seed=0)
t2 = time.perf_counter()
atoms.calc = FanCalculator(h=2.6 * dx, dx=dx, domain=domain, dim=2)
opt = make_optimizer("fan", atoms)
opt.run(fmax=0.0, steps=1)
t3 = time.perf_counter()
print(t1 - t0, t2 - t1, t3 - t2)
"""


def scene():
    from ase_sphrelax.build import fill
    from ase_sphrelax.domains import Circle

    domain, dx = Circle((0.5, 0.5), 0.2), 1 / 256
    return domain, dx, fill(domain, dx, jitter=0.1, seed=0)


def warm_evaluation(atoms0, domain, dx, repeats=20):
    from ase.calculators.calculator import all_changes

    from ase_sphrelax import FanCalculator

    atoms = atoms0.copy()
    calc = FanCalculator(h=2.6 * dx, dx=dx, domain=domain, dim=2)
    for _ in range(2):
        calc.calculate(atoms, ["energy", "forces"], all_changes)
    builds = calc.nlist.builds
    cpu, wall = [], []
    for k in range(repeats):
        atoms.positions[:, 0] += (1e-4 if k % 2 else -1e-4) * dx
        c0, t0 = time.process_time(), time.perf_counter()
        calc.calculate(atoms, ["energy", "forces"], all_changes)
        cpu.append(time.process_time() - c0)
        wall.append(time.perf_counter() - t0)
    assert calc.nlist.builds == builds
    return statistics.median(cpu), statistics.median(wall)


def demo_steps(atoms0, domain, dx, steps):
    from tqdm.auto import tqdm

    from ase_sphrelax import FanCalculator
    from ase_sphrelax.drivers import make_optimizer

    atoms = atoms0.copy()
    atoms.calc = FanCalculator(h=2.6 * dx, dx=dx, domain=domain, dim=2)
    opt = make_optimizer("fan", atoms)
    opt.run(fmax=0.0, steps=1)  # the first (one-shot) evaluation and the list build are not per-step costs
    bar = tqdm(total=steps, unit="step", disable=None, mininterval=0.5)

    def update():  # as the CLI's progress observer
        bar.update(1)
        if opt.nsteps % 25 == 0:
            bar.set_postfix(E=f"{atoms.get_potential_energy():.6e}")

    opt.attach(update, interval=1)
    builds = atoms.calc.nlist.builds
    c0, t0 = time.process_time(), time.perf_counter()
    opt.run(fmax=0.0, steps=steps)
    cpu, wall = time.process_time() - c0, time.perf_counter() - t0
    bar.close()
    return cpu / steps, wall / steps, atoms.calc.nlist.builds - builds


def first_step(repeats):
    env = dict(os.environ)
    root = Path(__file__).resolve().parent.parent
    env["PYTHONPATH"] = str(root) + os.pathsep + env.get("PYTHONPATH", "")
    subprocess.run([sys.executable, "-c", FIRST_STEP], env=env, check=True, capture_output=True)  # warm the cache
    rows = []
    for _ in range(repeats):
        out = subprocess.run([sys.executable, "-c", FIRST_STEP], env=env, check=True, capture_output=True, text=True)
        rows.append([float(x) for x in out.stdout.split()])
    return dict(imports=statistics.median(r[0] for r in rows), scene=statistics.median(r[1] for r in rows),
                first_step=statistics.median(r[2] for r in rows), all=rows)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--out", default=str(Path(__file__).parent / "results" / "bench_small.json"))
    args = parser.parse_args(argv)
    load_start = os.getloadavg()
    domain, dx, atoms0 = scene()
    warm_evaluation(atoms0, domain, dx, 3)  # compile / load
    warm, warm_wall, step, step_wall, rebuilds = [], [], [], [], []
    for _ in range(args.repeats):
        c, w = warm_evaluation(atoms0, domain, dx)
        warm.append(c)
        warm_wall.append(w)
        c, w, b = demo_steps(atoms0, domain, dx, args.steps)
        step.append(c)
        step_wall.append(w)
        rebuilds.append(b)
    first = first_step(args.repeats)
    med_warm, med_step = statistics.median(warm), statistics.median(step)
    result = dict(version=git_version(), started=time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
                  n=len(atoms0), steps=args.steps, repeats=args.repeats, warm_evaluation_cpu_s=med_warm,
                  demo_step_cpu_s=med_step, ratio_step_over_warm=med_step / med_warm,
                  warm_evaluation_wall_s=statistics.median(warm_wall), demo_step_wall_s=statistics.median(step_wall),
                  rebuilds_per_run=rebuilds, warm_all=warm, step_all=step, first_step=first,
                  load_average_start=load_start, load_average_end=os.getloadavg())
    print(f"N = {len(atoms0)}: warm evaluation {1e3 * med_warm:.2f} ms CPU "
          f"({1e3 * result['warm_evaluation_wall_s']:.2f} wall), demo step {1e3 * med_step:.2f} ms CPU "
          f"({1e3 * result['demo_step_wall_s']:.2f} wall; {statistics.median(rebuilds)} rebuilds in {args.steps} "
          f"steps), ratio {med_step / med_warm:.2f} (target <= 1.3)")
    print(f"first step on a warm cache: {first['first_step']:.3f} s (target < 1 s); imports {first['imports']:.3f} s, "
          f"scene {first['scene']:.3f} s")
    print(f"load average {load_start[0]:.2f} -> {os.getloadavg()[0]:.2f}")
    write_json(args.out, result)
    return result


if __name__ == "__main__":
    main()
