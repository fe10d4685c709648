"""One rebuild's fused scan on Fan's sphere at 1e6 (``benchmarks/bench_fan_1e6.py``'s 3D start, skin 0.1 h): the
general build loop (a candidate within max(cut-offs) + skin, the canonical orientation of an original-ghost pair,
found once by a wide point's stencil) against the plain one (:attr:`ase_sphrelax.neighbors.NeighborList.plain`: the
distance alone), each called directly on all points on one thread (the best of 3), and the same list from both.

    NUMBA_NUM_THREADS=1 python reproductions/speed-fan-1e6/build_loops.py results/build_loops_3d.json
"""
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))

import bench_fan_1e6 as bf  # noqa: E402

from ase_sphrelax import FanCalculator  # noqa: E402
from ase_sphrelax.kernel_sums import PAIR_FORCES  # noqa: E402
from ase_sphrelax.neighbors import NeighborList  # noqa: E402


def main(out=None, repeat=3):
    domain, dx, atoms = bf.scene(3, 1e6)
    h = bf.RATIO * dx
    kernel = FanCalculator(h=h, dx=dx, domain=domain).kernel
    r_pc = atoms.positions.copy()
    nlist = NeighborList(h, skin=0.1 * h)
    nlist.update(r_pc, atoms.cell, atoms.pbc)
    assert nlist.plain
    x_sc = nlist.points.extend(r_pc)
    arrays = nlist.build_arrays()
    n_ext = x_sc.shape[0]
    params = (1.0 / h, 1.0)
    record = dict(n=n_ext, h_over_dx=bf.RATIO, skin_over_h=0.1, repeat=repeat, loops={})
    lists = {}
    for kind in ("build", "build_plain"):
        loop = PAIR_FORCES.loop(kind, kernel, False, reach_test=False)
        pair_j = np.empty(60 * n_ext, dtype=np.int32)
        count_s = np.empty(n_ext + 1, dtype=np.int64)
        out_k = (np.zeros((n_ext, 3)),)
        loop(x_sc, *arrays, count_s, pair_j, 0, h * h, params, (), out_k, 0, 0, 1000)  # compiled
        times = []
        for _ in range(repeat):
            t = time.perf_counter()
            _, pos = loop(x_sc, *arrays, count_s, pair_j, 0, h * h, params, (), out_k, 0, 0, n_ext)
            times.append(time.perf_counter() - t)
        lists[kind] = pair_j[:pos].copy()
        record["loops"][kind] = dict(seconds=min(times), times=times, pairs_per_point=pos / n_ext)
    record["same_list"] = bool(np.array_equal(lists["build"], lists["build_plain"]))
    record["plain_over_general"] = record["loops"]["build_plain"]["seconds"] / record["loops"]["build"]["seconds"]
    record.update(threads=1, load_average=os.getloadavg(), command="NUMBA_NUM_THREADS=1 python "
                  "reproductions/speed-fan-1e6/build_loops.py " + (out or ""),
                  version=subprocess.run(["git", "describe", "--always", "--dirty"], capture_output=True, text=True,
                                         cwd=ROOT).stdout.strip())
    print(json.dumps(record, indent=1))
    if out:
        (Path(__file__).parent / out).write_text(json.dumps(record, indent=1) + "\n")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else None)
