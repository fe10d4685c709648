"""Peak memory per particle of FanCalculator at 1e6 particles, 2D and 3D (issue 9, item 5).

Each case runs in a fresh process (numba cache warm; the loops are compiled or loaded on
a small system first, so compilation is not counted):

1. the Atoms object is built (periodic jittered lattice, h = 2.6 dx, as ``bench_lammps.py``);
2. the peak-RSS counter is reset (``/proc/self/clear_refs``, Linux) and the resident set
   is read: the baseline, Atoms included;
3. ``evaluation``: the first evaluation (one-shot scan) and then two more, the second of
   which builds the Verlet list and the third reuses it (old results dropped before each,
   as ASE does); or ``relaxation fan`` / ``relaxation fire``: ``--steps`` steps of
   ``make_optimizer("fan")`` (Eq. 2.4) or ``make_optimizer("fire")`` (list rebuilds included;
   ASE's optimiser state and its per-step copies of forces and positions are counted);
4. the peak RSS (VmHWM) minus the baseline, per particle.

The figure excludes the Atoms object the user built, not the copy that ASE's
``Calculator.calculate`` keeps (``calc.atoms``, 32 B per particle: positions and numbers),
which is reported separately. Targets: < 300 B per particle in 2D, < 600 in 3D.

    python benchmarks/bench_memory.py [--n 1e6] [--threads 1,2] [--steps 20]

Writes ``benchmarks/results/bench_memory.json``.
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
    from _provenance import git_version, write_json
except ImportError:
    from benchmarks._provenance import git_version, write_json

WORKER = r"""
import json, sys, numba, numpy as np
from ase.calculators.calculator import all_changes
from ase_sphrelax import FanCalculator
from ase_sphrelax.build import periodic_box
from ase_sphrelax.drivers import make_optimizer

def status(key):
    for line in open("/proc/self/status"):
        if line.startswith(key):
            return int(line.split()[1]) * 1024
    raise KeyError(key)

n, dim, threads, case, steps = float(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]), sys.argv[4], int(sys.argv[5])
numba.set_num_threads(threads)
def box(side):
    return periodic_box((side,) * dim, dx=1.0, dim=dim, lattice="square" if dim == 2 else "cubic", jitter=0.25, seed=0)
small = box(12 if dim == 3 else 40)
small.calc = FanCalculator(h=2.6, dx=1.0, dim=dim)
make_optimizer("fire", small, backend="ase").run(fmax=0.0, steps=3)  # compile or load every loop
atoms = box(int(round(n ** (1.0 / dim))))
with open("/proc/self/clear_refs", "w") as f:
    f.write("5")
base = status("VmRSS")
calc = FanCalculator(h=2.6, dx=1.0, dim=dim)
if case == "evaluation":
    for k in range(3):
        if k:
            atoms.positions[:, 0] += 0.6 * calc.skin if k == 1 else 1e-3
        calc.reset()  # as ASE's get_property does when the atoms changed: old results are dropped
        calc.calculate(atoms, ["energy", "forces"], all_changes)
    builds = calc.nlist.builds
else:
    atoms.calc = calc
    # ASE's optimisers, as the stored record measured (bench_optimizers.py measures SPHFIRE/SPHLBFGS)
    make_optimizer(case.split()[1], atoms, backend="ase").run(fmax=0.0, steps=steps)
    builds = calc.nlist.builds
peak = status("VmHWM")
print(json.dumps(dict(n=len(atoms), base=base, peak=peak, builds=builds, pairs=int(calc.nlist.pair_j.shape[0]),
                      n_extended=int(calc.nlist.n_extended))))
"""


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--n", type=float, default=1e6)
    parser.add_argument("--dims", default="2,3")
    parser.add_argument("--threads", default="1,2")
    parser.add_argument("--steps", type=int, default=20)
    parser.add_argument("--cases", default="evaluation,relaxation fan,relaxation fire")
    parser.add_argument("--out", default=str(Path(__file__).parent / "results" / "bench_memory.json"))
    args = parser.parse_args(argv)
    env = dict(os.environ)
    root = Path(__file__).resolve().parent.parent
    env["PYTHONPATH"] = str(root) + os.pathsep + env.get("PYTHONPATH", "")
    rows = []
    for dim in [int(d) for d in args.dims.split(",")]:
        for threads in [int(t) for t in args.threads.split(",")]:
            for case in args.cases.split(","):
                out = subprocess.run([sys.executable, "-c", WORKER, str(args.n), str(dim), str(threads), case,
                                      str(args.steps)], env=env, check=True, capture_output=True, text=True)
                row = json.loads(out.stdout.strip().splitlines()[-1])
                row.update(dim=dim, threads=threads, case=case,
                           bytes_per_particle=(row["peak"] - row["base"]) / row["n"],
                           ase_atoms_copy_bytes_per_particle=32.0,
                           target=300 if dim == 2 else 600)
                rows.append(row)
                print(f"{dim}D N={row['n']} threads={threads} {case:15s}: peak RSS - baseline = "
                      f"{row['bytes_per_particle']:.0f} B/particle (of which ASE's Atoms copy 32; target "
                      f"< {row['target']}), {row['pairs'] / row['n']:.1f} list entries per particle, "
                      f"{row['builds']} builds", flush=True)
    result = dict(version=git_version(), started=time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
                  load_average=os.getloadavg(), rows=rows)
    write_json(args.out, result)
    return result


if __name__ == "__main__":
    main()
