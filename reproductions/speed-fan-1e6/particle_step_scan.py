"""Does cutting each particle's move in one FIRE step leave fewer list rebuilds, and a shorter run to the bench's
target, on Fan's circle and sphere?

The question, declared before the runs: in 3D the list's skin stays 0.1 h and its rebuilds are set off by a few
fast particles (``walk_floor_3d.py``, question 3). SPHFIRE's ``max_particle_step`` cuts the move of each particle
that would go further in one step (its velocity kept). For each cut (in units of h; "none" is ASE's step) on the
bench's start (``bench_fan_1e6.run_ours``: fill, FanCalculator, ``make_optimizer("fire")`` with the cut, the
interior mean h|sum V grad W| checked every 5 steps until 6e-4), the wall time, steps and list builds, on 2
threads, the cuts alternating within each repeat (the median of the repeats decides). The default is the cut
that gives the shortest wall time, per dimension, unless the steps grow by more than 10 %; at 1e6 the two best
cuts of 1e5 in 3D, the best one in 2D, and no cut, alternating twice: where 1e6 differs from 1e5, 1e6 decides.

    NUMBA_NUM_THREADS=2 python reproductions/speed-fan-1e6/particle_step_scan.py --n 1e5 --repeats 3 \
        --out reproductions/speed-fan-1e6/results/particle_step_scan.json
    NUMBA_NUM_THREADS=2 python reproductions/speed-fan-1e6/particle_step_scan.py --n 1e6 --dims 3 \
        --cuts none,0.005,0.0065 --repeats 2 --out reproductions/speed-fan-1e6/results/particle_step_scan_3d_1e6.json
    NUMBA_NUM_THREADS=2 python reproductions/speed-fan-1e6/particle_step_scan.py --n 1e6 --dims 2 \
        --cuts none,0.01 --repeats 2 --out reproductions/speed-fan-1e6/results/particle_step_scan_2d_1e6.json
"""
import argparse
import os
import sys
from pathlib import Path

import numba
import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))

CUTS = "none,0.0035,0.005,0.0065,0.01,0.015,0.02"


def scan(dims, n, cuts, repeats):
    import bench_fan_1e6 as bf

    rows = []
    for dim in dims:
        bf.warm_up(dim)
        for _ in range(repeats):  # the cuts alternate within each repeat
            for cut in cuts:
                step = None if cut is None else cut * bf.RATIO * bf.scene_dx(dim, n)  # cut * h
                run = bf.run_ours(dim, n, 6e-4, 5, 2000, max_particle_step=step)
                rows.append(dict(dim=dim, cut_over_h=cut, n=run["n"], wall_time=run["wall_time"], steps=run["steps"],
                                 list_builds=run["list_builds"], final_measure=run["final_measure"],
                                 reached=run["reached"]))
                print(f"{dim}D cut {cut}: {run['wall_time']:.2f} s, {run['steps']} steps, "
                      f"{run['list_builds']} builds", flush=True)
    return rows


def main():
    from _provenance import git_version, write_json

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=float, default=1e5)
    parser.add_argument("--dims", default="2,3")
    parser.add_argument("--cuts", default=CUTS, help=f"cuts in units of h, 'none' for ASE's step (default {CUTS})")
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    cuts = [None if c == "none" else float(c) for c in args.cuts.split(",")]
    rows = scan([int(d) for d in args.dims.split(",")], int(args.n), cuts, args.repeats)
    write_json(args.out, dict(version=git_version(), threads=numba.get_num_threads(), load_average=os.getloadavg(),
                              n=int(args.n), runs=rows, medians=medians(rows)))


def medians(rows):
    """Per dimension and cut: the median wall time over the repeats, and the steps and builds (the same in every
    repeat: the runs are deterministic)."""
    out = []
    for key in dict.fromkeys((r["dim"], r["cut_over_h"]) for r in rows):
        runs = [r for r in rows if (r["dim"], r["cut_over_h"]) == key]
        out.append(dict(dim=key[0], cut_over_h=key[1], runs=len(runs),
                        wall_time=float(np.median([r["wall_time"] for r in runs])),
                        steps=sorted({r["steps"] for r in runs}), list_builds=sorted({r["list_builds"] for r in runs})))
    return out


if __name__ == "__main__":
    main()
