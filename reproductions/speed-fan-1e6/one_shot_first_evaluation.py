"""The first evaluation (one-shot bins, no list kept) by the plain build's loop against the general scan.

A fresh ``FanCalculator`` on the bench's start (``benchmarks/bench_fan_1e6.py``'s scene: Fan's circle or sphere
filled at 1e6 particles, h = 2.6 dx) evaluates its forces once: with ``NeighborList.one_shot_scan`` (the plain
build's loop into a region each thread writes over, the default on bins without images and of one cut-off) and
without it (the general one-shot scan, which tests each candidate with a branch), alternated ``--repeats`` times in
one process on ``--threads`` numba threads (numba compiled first, on a small system). Stores the wall time of each
``get_forces`` call and the largest force difference between the two paths (round-off: the terms summed in another
order).

    python reproductions/speed-fan-1e6/one_shot_first_evaluation.py --dims 2,3 --repeats 3 \
        --out reproductions/speed-fan-1e6/results/one_shot_first_evaluation.json
"""
import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))


def main(argv=None):
    import bench_fan_1e6 as bench
    import numba
    from _provenance import git_version, write_json

    from ase_sphrelax import FanCalculator
    from ase_sphrelax.neighbors import NeighborList

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--dims", default="2,3")
    parser.add_argument("--n", type=float, default=1e6)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args(argv)
    numba.set_num_threads(args.threads)
    plain_scan = NeighborList.one_shot_scan
    result = dict(version=git_version(), started=time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
                  load_average_start=os.getloadavg(), threads=args.threads, n=args.n, scenes={},
                  command="python reproductions/speed-fan-1e6/one_shot_first_evaluation.py " + " ".join(argv or []))
    for dim in [int(d) for d in args.dims.split(",")]:
        bench.warm_up(dim)
        domain, dx, atoms = bench.scene(dim, args.n)
        times, forces = {"plain": [], "general": []}, {}
        for _ in range(args.repeats):
            for path in ("plain", "general"):
                if path == "general":
                    del NeighborList.one_shot_scan  # PairInteraction.compute then runs the general scan
                try:
                    atoms.calc = FanCalculator(h=bench.RATIO * dx, dx=dx, domain=domain)
                    atoms.calc.silence_scale_hint()
                    t0 = time.perf_counter()
                    forces[path] = atoms.get_forces()
                    times[path].append(time.perf_counter() - t0)
                finally:
                    NeighborList.one_shot_scan = plain_scan
        scale = float(np.abs(forces["general"]).max())
        result["scenes"][f"{dim}D"] = dict(n=len(atoms), seconds=times,
                                          median={k: float(np.median(v)) for k, v in times.items()},
                                          max_force_difference_relative=float(
                                              np.abs(forces["plain"] - forces["general"]).max() / scale))
        print(f"{dim}D n={len(atoms)}: plain {np.round(times['plain'], 3)} s, "
              f"general {np.round(times['general'], 3)} s")
    result["load_average_end"] = os.getloadavg()
    write_json(args.out, result)


if __name__ == "__main__":
    main(sys.argv[1:])
