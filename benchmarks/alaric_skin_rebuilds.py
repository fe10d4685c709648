"""Verlet-list rebuilds of ALARICDynamics against the skin (issue 20 item 4): the Fig. 13 case (uniform density in
the unit circle, one uniformly random start, wall boundary, log form), ``--steps`` steps, the list builds counted
per 500 steps, for each skin factor (skin = factor * mean H at the first evaluation; the calculator's default is
``alaric.SKIN_FACTOR``).

    OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/alaric_skin_rebuilds.py --n 2000 --steps 3000 \
        --out benchmarks/results/alaric_skin_rebuilds.json
"""
import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from ase_sphrelax import ALARICCalculator
from ase_sphrelax.domains import Circle
from ase_sphrelax.drivers.alaric_dynamics import ALARICDynamics

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "examples"))
from alaric_reproduce import circle_start, uniform_density  # noqa: E402 (the Fig. 13 start)


def run(n, steps, seed, factor):
    atoms = circle_start(n, seed)
    probe = ALARICCalculator(target_density=uniform_density, dim=2, domain=Circle((0.0, 0.0), 1.0), form="log")
    probe.calculate(atoms.copy(), ["energy"])
    skin = factor * float(np.mean(probe.h_p))
    calc = ALARICCalculator(target_density=uniform_density, target_gradient=lambda x: np.zeros_like(x), dim=2,
                            domain=Circle((0.0, 0.0), 1.0), skin=skin, form="log")
    atoms.calc = calc
    dyn = ALARICDynamics(atoms, eps_dot_min=0.0, eps_min=0.0)
    builds_s = []
    dyn.attach(lambda: builds_s.append(int(calc.nlist.builds)), interval=1)
    t0, c0 = time.perf_counter(), time.process_time()
    dyn.run(steps)
    window = 500
    per_window = [builds_s[min(k + window, len(builds_s) - 1)] - builds_s[k] for k in range(0, len(builds_s) - 1, window)]
    return dict(factor=factor, skin=skin, mean_h_start=skin / factor, steps=steps, evaluations=calc.evaluations,
                builds=int(calc.nlist.builds), builds_per_500_steps=per_window,
                pairs_last=int(calc.nlist._pair_count),
                wall_s=time.perf_counter() - t0, cpu_s=time.process_time() - c0,
                epsilon=float(calc.results["epsilon"]) if "epsilon" in calc.results else None)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=2000)
    ap.add_argument("--steps", type=int, default=3000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--factors", default="0.2,0.1,0.05")
    ap.add_argument("--out", default="benchmarks/results/alaric_skin_rebuilds.json")
    a = ap.parse_args()
    rows = []
    for factor in [float(f) for f in a.factors.split(",")]:
        row = run(a.n, a.steps, a.seed, factor)
        print(json.dumps(row), flush=True)
        rows.append(row)
    out = dict(command=" ".join(sys.argv), load=os.getloadavg(), n=a.n, steps=a.steps, seed=a.seed, rows=rows)
    Path(a.out).write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
