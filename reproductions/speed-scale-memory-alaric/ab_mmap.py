"""What fixing glibc's mmap threshold costs in CPU: steps with the threshold at 64 KiB (``sph.MMAP_THRESHOLD``, B)
and at 32 MiB (glibc's dynamic threshold at its ceiling, A), interleaved in one process on one numba thread.

ALARIC (``alaric2d``/``alaric3d``): bench_scale.py's scene and dynamics, 3 warm-up steps, then ``ROUNDS`` rounds of
``BLOCK`` steps with each setting (A B, B A, ...); ``parvi2d``: one ``ParVISampler.run`` of ``BLOCK`` steps per
block. The CPU time of the calling thread (``time.thread_time``, page faults included) per step, and the median of
the rounds' ratios B / A; as the CPU times vary with the machine's load, also the minor page faults per step (the
thread's ``getrusage``: what a fixed threshold adds) and the CPU time of one fresh page, measured in the same
process (a 64 MB mapping touched once), whose product is the added cost without the load's noise. A fixed
threshold changes no arithmetic: the trajectories are the same either way.

    python reproductions/speed-scale-memory-alaric/ab_mmap.py \
        alaric2d:1e4:8:30,alaric2d:1e5:8:6,parvi2d:1e5:4:6,alaric3d:1e5:4:4 \
        > reproductions/speed-scale-memory-alaric/results/ab_mmap.json

(each ``METHOD:N:ROUNDS:BLOCK``, one after the other in the one process).
"""
import ctypes
import json
import resource
import sys
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))


def main(method, n, rounds, block):
    import numba
    import numpy as np

    import bench_scale as B
    from _provenance import git_version

    warnings.simplefilter("ignore")
    numba.set_num_threads(1)
    libc = ctypes.CDLL(None)
    threshold = dict(A=32 * 2**20, B=64 * 1024)
    if method.startswith("alaric"):
        atoms, run = B.setup(method, n)
        dim = B.DIM[method]
        dyn = B.alaric_dynamics(atoms, dim, B._alaric_domain(dim, n))
        dyn.run(3)

        def work():
            dyn.run(block)
    else:
        from ase_sphrelax.sampling import ParVISampler, get_target

        target = get_target("gaussian")

        def work():
            ParVISampler(target.log_density, target.score, dim=2, n=int(n), steps=block, check=False, seed=0).run()
        work()
    cpu, faults = dict(A=[], B=[]), dict(A=[], B=[])
    for r in range(rounds):
        for k in ("AB" if r % 2 == 0 else "BA"):
            libc.mallopt(-3, threshold[k])  # M_MMAP_THRESHOLD
            f0 = resource.getrusage(resource.RUSAGE_THREAD).ru_minflt
            t = time.thread_time()
            work()
            cpu[k].append((time.thread_time() - t) / block)
            faults[k].append((resource.getrusage(resource.RUSAGE_THREAD).ru_minflt - f0) / block)
    ratios = [b / a for a, b in zip(cpu["A"], cpu["B"])]
    fault_cost = []  # CPU seconds per fresh page: a 64 MB mapping (above either threshold) touched once
    for _ in range(5):
        t = time.thread_time()
        np.ones(2**23)
        fault_cost.append((time.thread_time() - t) / (2**26 / 4096))
    added = (np.median(faults["B"]) - np.median(faults["A"])) * float(np.median(fault_cost))
    return dict(method=method, n=n, rounds=rounds, block=block, threshold_bytes=threshold, version=git_version(),
                cpu_per_step=cpu, ratios=ratios, ratio_B_over_A=float(np.median(ratios)), minor_faults_per_step=faults,
                cpu_per_fresh_page=float(np.median(fault_cost)), added_cpu_per_step=float(added),
                added_fraction=float(added / np.median(cpu["A"])))


if __name__ == "__main__":
    rows = []
    for spec in sys.argv[1].split(","):
        method, n, rounds, block = spec.split(":")
        rows.append(main(method, float(n), int(rounds), int(block)))
    print(json.dumps(dict(rows=rows), indent=1))
