"""Optimiser step cost against one force evaluation, and peak memory: SPHFIRE/SPHLBFGS vs ASE's (issue 33, item 1).

Fan's circle (2D, radius 0.2) or sphere (3D, radius 0.2) filled at the ``dx`` that gives about
``N`` particles (``fill(..., jitter=0.1, seed=0)``, h = 2.6 dx, ``FanCalculator`` with the
domain), relaxed by ``make_optimizer(name, atoms)`` (``backend="sph"``: the default,
:mod:`ase_sphrelax.drivers.sph_optimizers`) and ``make_optimizer(name, atoms, backend="ase")``
(ASE's FIRE / LBFGS, the same step scale; LBFGS with ASE's history of 20 pairs that
``make_optimizer`` gave it before).

* ``timing`` (one process per dimension, size and optimiser): three copies of the particles,
  one relaxed by ours, one by ASE's, one only evaluated. ``--rounds`` interleaved rounds of
  ``--steps`` steps each (the order rotates), after two warm-up steps. A step's time is the
  whole ``run`` per step (the optimiser's work, the constraints, ASE's copies and the force
  evaluation). The headline ratio ``step_over_evaluation`` divides it by the time spent inside
  the calculator's ``calculate`` in the same steps (the force evaluations of that run, its
  neighbour-list rebuilds included), per round, the median reported. ``static`` ratios divide
  by the third copy's evaluations after a displacement of 1e-6 dx (the list always reused: a
  lower bound of an evaluation). The load average is stored before and after. After the rounds both relaxations have taken the same steps from
  the same start: their energies and largest forces are stored (the convergence per step).
* ``memory`` (one fresh process per case): the particles are built, numba is warm, then the
  peak-RSS counter is reset (``/proc/self/clear_refs``; ``resource.getrusage`` maxrss cannot
  be reset and would hold the peak of ``fill``) and ``--memory-steps`` steps run; peak RSS
  (VmHWM) minus the RSS before the calculator was made, per particle: the calculator, its
  neighbour list, ASE's copies and the optimiser, beyond the user's Atoms. The process's
  ``ru_maxrss`` is stored too. The case ``evaluation`` makes the calculator and evaluates it
  ``--memory-steps`` times without an optimiser (``--cases`` picks cases). ``trace`` holds the peak
  so far after each evaluation or step (the optimiser's observer, called after the step's evaluation).
* ``convergence`` (small, in this process): the 2D circle at dx = 1/160 and the 3D sphere at
  dx = 1/50, ``--conv-steps`` LBFGS steps with ours at several history lengths against ASE's
  (history 20): energy and the mean kernel-gradient error (``quality_summary``) every 100 steps.

    python benchmarks/bench_optimizers.py [--sizes 1e5,1e6] [--dims 2,3] [--threads 2]
        [--memory-sizes 1e6] [--rounds 3] [--steps 3] [--memory-steps 8] [--parts timing,memory,convergence]
        [--merge]

Writes ``benchmarks/results/bench_optimizers.json``.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

try:
    from _provenance import git_version, machine, write_json
except ImportError:
    from benchmarks._provenance import git_version, machine, write_json

SETUP = r"""
import json, os, resource, sys, time, warnings
import numba, numpy as np
from ase_sphrelax import FanCalculator
from ase_sphrelax.build import fill
from ase_sphrelax.domains import Circle, Sphere
from ase_sphrelax.drivers import make_optimizer
warnings.simplefilter("ignore")

def status(key):
    for line in open("/proc/self/status"):
        if line.startswith(key):
            return int(line.split()[1]) * 1024
    raise KeyError(key)

def case(n, dim):
    domain = Circle((0.5, 0.5), 0.2) if dim == 2 else Sphere((0.5, 0.5, 0.5), 0.2)
    measure = np.pi * 0.2 ** 2 if dim == 2 else 4 / 3 * np.pi * 0.2 ** 3
    dx = (measure / n) ** (1.0 / dim)
    return domain, dx, fill(domain, dx, jitter=0.1, seed=0)

def calculator(domain, dx, dim):
    return FanCalculator(h=2.6 * dx, dx=dx, domain=domain, dim=dim)

def options(name, backend, memory=None):
    # make_optimizer's keywords of a case: ours with ASE's FIRE step (no cut: the same trajectory as ASE's FIRE),
    # SPHLBFGS with ``memory`` pairs when given
    if name == "fire" and backend == "sph":
        return {"max_particle_step": None}
    return {"memory": memory} if (name == "lbfgs" and backend == "sph" and memory) else {}

def warm(dim, memory):
    domain, dx, small = case(3000, dim)
    for name in ("fire", "lbfgs"):
        for backend in ("sph", "ase"):
            atoms = small.copy()
            atoms.calc = calculator(domain, dx, dim)
            make_optimizer(name, atoms, backend=backend, **options(name, backend, memory)).run(fmax=0.0, steps=3)
"""

TIMING = SETUP + r"""
n, dim, threads, name, rounds, steps, memory = (float(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]), sys.argv[4],
                                                int(sys.argv[5]), int(sys.argv[6]), json.loads(sys.argv[7]))
numba.set_num_threads(threads)
warm(dim, memory)
domain, dx, atoms0 = case(n, dim)
runs = {}
for backend in ("sph", "ase"):
    atoms = atoms0.copy()
    calc = atoms.calc = calculator(domain, dx, dim)
    spent = [0.0]
    def timed(*a, _calculate=calc.calculate, _spent=spent, **k):
        t0 = time.perf_counter()
        try:
            return _calculate(*a, **k)
        finally:
            _spent[0] += time.perf_counter() - t0
    calc.calculate = timed  # the time of each force evaluation inside the run
    opt = make_optimizer(name, atoms, backend=backend, **options(name, backend, memory))
    opt.run(fmax=0.0, steps=2)  # first evaluation, list build
    runs[backend] = (atoms, opt, spent)
probe = atoms0.copy()
probe.calc = calculator(domain, dx, dim)
probe.get_forces(); probe.positions[:, 0] += 1e-9 * dx; probe.get_forces()  # one-shot, then the list
rng = np.random.default_rng(0)
def evaluate():
    probe.positions[:, :dim] += rng.uniform(-1e-6, 1e-6, (len(probe), dim)) * dx
    probe.get_forces()
times = {"sph": [], "ase": [], "evaluation": [], "sph_in_calculator": [], "ase_in_calculator": []}
order = ["sph", "ase", "evaluation"]
for r in range(rounds):
    for who in order[r % 3:] + order[: r % 3]:
        t0 = time.perf_counter()
        if who == "evaluation":
            for _ in range(steps):
                evaluate()
        else:
            spent = runs[who][2]
            spent[0] = 0.0
            runs[who][1].run(fmax=0.0, steps=steps)
            times[who + "_in_calculator"].append(spent[0] / steps)
        times[who].append((time.perf_counter() - t0) / steps)
out = dict(n=len(atoms0), dx=dx, times=times,
           ratio_sph=[a / b for a, b in zip(times["sph"], times["sph_in_calculator"])],
           ratio_ase=[a / b for a, b in zip(times["ase"], times["ase_in_calculator"])],
           ratio_sph_static=[a / b for a, b in zip(times["sph"], times["evaluation"])],
           ratio_ase_static=[a / b for a, b in zip(times["ase"], times["evaluation"])])
for backend, (atoms, opt, _) in runs.items():
    out["energy_" + backend] = float(atoms.get_potential_energy())
    out["fmax_" + backend] = float(np.linalg.norm(atoms.get_forces(), axis=1).max())
    out["steps_" + backend] = int(opt.nsteps)
    out["class_" + backend] = type(opt).__name__
    out["memory_" + backend] = getattr(opt, "memory", None)
print(json.dumps(out))
"""

MEMORY = SETUP + r"""
n, dim, threads, what, steps, memory = (float(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]), sys.argv[4],
                                        int(sys.argv[5]), json.loads(sys.argv[6]))
numba.set_num_threads(threads)
warm(dim, memory)
domain, dx, atoms = case(n, dim)
with open("/proc/self/clear_refs", "w") as f:
    f.write("5")
base = status("VmRSS")
atoms.calc = calculator(domain, dx, dim)
cls = None
trace = []  # the peak so far after each evaluation or step, bytes per particle beyond the Atoms
def record():
    trace.append(round((status("VmHWM") - base) / len(atoms), 1))
if what == "evaluation":
    for k in range(steps):
        atoms.positions[:, 0] += 1e-6 * dx
        atoms.get_forces()
        record()
else:
    backend, name = what.split()
    opt = make_optimizer(name, atoms, backend=backend, **options(name, backend, memory))
    opt.attach(record, interval=1)
    opt.run(fmax=0.0, steps=steps)
    cls = type(opt).__name__
peak = status("VmHWM")
print(json.dumps(dict(n=len(atoms), base=base, peak=peak, cls=cls, trace=trace,
                      ru_maxrss=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024)))
"""


def _run(script, args, env):
    out = subprocess.run([sys.executable, "-c", script, *map(str, args)], env=env, check=True, capture_output=True,
                         text=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def _median(values):
    values = sorted(values)
    k = len(values) // 2
    return values[k] if len(values) % 2 else 0.5 * (values[k - 1] + values[k])


def convergence(steps, memories):
    """Energy and mean gradient error every 100 steps: ours at ``memories`` against ASE's LBFGS (20)."""
    import warnings

    from ase_sphrelax import FanCalculator
    from ase_sphrelax.analysis.quality import quality_summary
    from ase_sphrelax.build import fill
    from ase_sphrelax.domains import Circle, Sphere
    from ase_sphrelax.drivers import make_optimizer

    warnings.simplefilter("ignore")
    rows = []
    for dim in (2, 3):
        domain, dx = (Circle((0.5, 0.5), 0.2), 1 / 160) if dim == 2 else (Sphere((0.5, 0.5, 0.5), 0.2), 1 / 50)
        atoms0 = fill(domain, dx, jitter=0.1, seed=0)
        for backend, memory in [("ase", 20)] + [("sph", m) for m in memories]:
            atoms = atoms0.copy()
            atoms.calc = FanCalculator(h=2.6 * dx, dx=dx, domain=domain, dim=dim)
            opt = make_optimizer("lbfgs", atoms, backend=backend, memory=memory)
            row = dict(dim=dim, n=len(atoms), backend=backend, memory=memory, steps=[], energy=[], gradient_error_mean=[])
            for _ in range(steps // 100):
                opt.run(fmax=0.0, steps=100)
                row["steps"].append(opt.nsteps)
                row["energy"].append(float(atoms.get_potential_energy()))
                row["gradient_error_mean"].append(
                    float(quality_summary(atoms, 2.6 * dx, dx=dx, domain=domain)["gradient_error_mean"]))
            print(f"convergence {dim}D N={row['n']} {backend} memory {memory}: E {row['energy']}, "
                  f"mean gradient error {row['gradient_error_mean']}", flush=True)
            rows.append(row)
    return rows


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--sizes", default="1e5,1e6", help="sizes of the timing part")
    parser.add_argument("--memory-sizes", default="1e6", help="sizes of the memory part")
    parser.add_argument("--dims", default="2,3")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--steps", type=int, default=3)
    parser.add_argument("--memory-steps", type=int, default=8)
    parser.add_argument("--memory", type=int, default=0, help="SPHLBFGS history (0: make_optimizer's default)")
    parser.add_argument("--parts", default="timing,memory,convergence")
    parser.add_argument("--cases", default="evaluation,sph fire,sph lbfgs,ase fire,ase lbfgs",
                        help="the memory part's cases, comma-separated")
    parser.add_argument("--conv-steps", type=int, default=300)
    parser.add_argument("--conv-memories", default="3,5,20")
    parser.add_argument("--merge", action="store_true",
                        help="keep the parts of an existing --out that this run does not make (each part records "
                             "its own command, commit, start and load)")
    parser.add_argument("--out", default=str(Path(__file__).parent / "results" / "bench_optimizers.json"))
    args = parser.parse_args(argv)
    root = Path(__file__).resolve().parent.parent
    env = dict(os.environ)
    env["PYTHONPATH"] = str(root) + os.pathsep + env.get("PYTHONPATH", "")
    parts = args.parts.split(",")
    run = dict(version=git_version(), started=time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
               command="python benchmarks/bench_optimizers.py " + " ".join(argv if argv is not None else sys.argv[1:]),
               threads=args.threads, cpus=os.cpu_count(), load_average_start=os.getloadavg(), machine=machine())
    result = dict(timing=[], memory=[], convergence=[], runs={part: run for part in parts})
    sizes = [float(s) for s in args.sizes.split(",")]
    memory_sizes = [float(s) for s in args.memory_sizes.split(",")]
    dims = [int(d) for d in args.dims.split(",")]
    if "memory" in parts:
        for n in memory_sizes:
            for dim in dims:
                for what in args.cases.split(","):
                    load = os.getloadavg()
                    row = _run(MEMORY, [n, dim, args.threads, what, args.memory_steps, args.memory], env)
                    row.update(dim=dim, case=what, load_before=load, load_after=os.getloadavg(),
                               bytes_per_particle=(row["peak"] - row["base"]) / row["n"])
                    result["memory"].append(row)
                    print(f"memory {dim}D N={row['n']} {what:11s}: {row['bytes_per_particle']:.0f} B/particle "
                          f"beyond the Atoms ({row['cls']}); load {load[0]:.1f}", flush=True)
    if "timing" in parts:
        for n in sizes:
            for dim in dims:
                for name in ("fire", "lbfgs"):
                    load = os.getloadavg()
                    row = _run(TIMING, [n, dim, args.threads, name, args.rounds, args.steps, args.memory], env)
                    row.update(dim=dim, name=name, load_before=load, load_after=os.getloadavg(),
                               step_over_evaluation_sph=_median(row["ratio_sph"]),
                               step_over_evaluation_ase=_median(row["ratio_ase"]),
                               step_over_static_evaluation_sph=_median(row["ratio_sph_static"]),
                               step_over_static_evaluation_ase=_median(row["ratio_ase_static"]),
                               energy_ratio_sph_over_ase=row["energy_sph"] / row["energy_ase"])
                    result["timing"].append(row)
                    print(f"timing {dim}D N={row['n']} {name}: step / evaluation: ours "
                          f"{row['step_over_evaluation_sph']:.2f} ({row['class_sph']}), ASE's "
                          f"{row['step_over_evaluation_ase']:.2f} (static evaluation {_median(row['times']['evaluation']):.3f}"
                          f" s: {row['step_over_static_evaluation_sph']:.2f}, "
                          f"{row['step_over_static_evaluation_ase']:.2f}); E after {row['steps_sph']} steps ours/ASE {row['energy_ratio_sph_over_ase']:.6f}; "
                          f"load {load[0]:.1f}", flush=True)
    if "convergence" in parts:
        result["convergence"] = convergence(args.conv_steps, [int(m) for m in args.conv_memories.split(",")])
    run["load_average_end"] = os.getloadavg()
    if args.merge and Path(args.out).exists():  # read at the end: another run may have written meanwhile
        old = json.loads(Path(args.out).read_text())
        for part in ("timing", "memory", "convergence"):
            if part not in parts and part in old:
                result[part] = old[part]
                result["runs"][part] = old.get("runs", {}).get(part)
    write_json(args.out, result)
    return result


if __name__ == "__main__":
    main()
