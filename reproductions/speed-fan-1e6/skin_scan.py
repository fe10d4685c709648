"""Fan's sphere in 3D: the largest adaptive skin (``MAX_SKIN_FACTOR[3]``, times the default 0.1 h) against the
time to the bench's target (``benchmarks/bench_fan_1e6.py``'s scene, optimiser and measure), each setting run
``--repeat`` times interleaved; the wall and CPU time, steps and list builds of each run.

    python reproductions/speed-fan-1e6/skin_scan.py --n 1e6 --threads 2 --factors 1,1.5 --repeat 2 \
        --out reproductions/speed-fan-1e6/results/skin_3d_1e6.json
    python reproductions/speed-fan-1e6/skin_scan.py --n 1e5 --threads 1 --factors 1,1.5 --repeat 2 \
        --out reproductions/speed-fan-1e6/results/skin_3d_1e5.json
"""
import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--n", type=float, default=1e6)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--factors", default="1,1.5")
    parser.add_argument("--repeat", type=int, default=2)
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args(argv)
    import numba

    numba.set_num_threads(args.threads)
    import bench_fan_1e6 as bf

    import ase_sphrelax.calculators.fan as fan

    bf.warm_up(3)
    runs = []
    for _ in range(args.repeat):
        for factor in [float(f) for f in args.factors.split(",")]:
            fan.MAX_SKIN_FACTOR[3] = factor
            cpu = time.process_time()
            ours = bf.run_ours(3, args.n, 6e-4, 5, 2000)
            runs.append(dict(max_skin_factor=factor, wall_time=ours["wall_time"], cpu_time=time.process_time() - cpu,
                             steps=ours["steps"], list_builds=ours["list_builds"], n=ours["n"],
                             final_measure=ours["final_measure"], load_average=os.getloadavg()))
            print(json.dumps(runs[-1]), flush=True)
    version = subprocess.run(["git", "describe", "--always", "--dirty"], capture_output=True, text=True,
                             cwd=ROOT).stdout.strip()
    record = dict(threads=args.threads, version=version, runs=runs,
                  command="python reproductions/speed-fan-1e6/skin_scan.py " + " ".join(argv or sys.argv[1:]))
    args.out.write_text(json.dumps(record, indent=1) + "\n")


if __name__ == "__main__":
    main()
