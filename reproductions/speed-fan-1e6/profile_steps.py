"""Where a FIRE step of Fan's 1e6 circle spends its wall time: the first STEPS steps of the timed run's start
(``benchmarks/bench_fan_1e6.py``'s scene and optimiser), the package's internal steps timed by
``benchmarks/profile_fan.py``'s wrappers, the calculator's whole evaluation, and what is left (the optimiser).

    NUMBA_NUM_THREADS=2 python reproductions/speed-fan-1e6/profile_steps.py 2 60 results/profile_2d_2t.json
    NUMBA_NUM_THREADS=1 python reproductions/speed-fan-1e6/profile_steps.py 2 60 results/profile_2d_1t.json
"""
import json
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))

import bench_fan_1e6 as bf  # noqa: E402
import profile_fan as pf  # noqa: E402

from ase_sphrelax import FanCalculator, make_optimizer  # noqa: E402


def main(dim=2, steps=60, out=None):
    pf.instrument()
    bf.warm_up(dim)
    pf.TIMES.clear()
    domain, dx, atoms = bf.scene(dim, 1e6)
    calc = atoms.calc = FanCalculator(h=bf.RATIO * dx, dx=dx, domain=domain)
    opt = make_optimizer("fire", atoms)
    calculate, spent = calc.calculate, [0.0]

    def timed(*args, **kwargs):
        t = time.perf_counter()
        calculate(*args, **kwargs)
        spent[0] += time.perf_counter() - t

    calc.calculate = timed
    t0 = time.perf_counter()
    opt.run(fmax=0.0, steps=steps)
    wall = time.perf_counter() - t0
    record = dict(n=len(atoms), steps=int(opt.nsteps), threads=int(os.environ.get("NUMBA_NUM_THREADS", "0")),
                  wall=wall, wall_per_step=wall / opt.nsteps, calculate=spent[0], builds=int(calc.nlist.builds),
                  seconds_by_part=dict(pf.TIMES), load_average=os.getloadavg(),
                  version=subprocess.run(["git", "describe", "--always", "--dirty"], capture_output=True, text=True,
                                         cwd=ROOT).stdout.strip())
    parts = record["seconds_by_part"]
    record["derived"] = dict(
        walk_each=parts.get("pair loop (list walk)", 0.0) / max(opt.nsteps - calc.nlist.builds, 1),
        rebuild_each=parts.get("bin scan + list + pairs (fused)", 0.0) / max(calc.nlist.builds, 1),
        outside_pair_sums_per_step=(wall - parts.get("pair compute", 0.0)) / opt.nsteps)
    print(json.dumps(record, indent=1))
    if out:
        Path(out).write_text(json.dumps(record, indent=1) + "\n")


if __name__ == "__main__":
    main(int(sys.argv[1]), int(sys.argv[2]), sys.argv[3] if len(sys.argv) > 3 else None)
