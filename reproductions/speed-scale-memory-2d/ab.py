"""What this entry's two memory changes cost in CPU: steps with (B) and without (A) each, interleaved in one process
on one numba thread (issue 33 item 4).

``METHOD:N:ROUNDS:BLOCK:WHAT`` (``alaric2d`` or ``bipi2d``, bench_scale.py's scenes, drivers and calculators);
``WHAT``: ``release``, :func:`ase_sphrelax.sph.release_pair_buffers` after each evaluation and viscous sum (A: it
replaced by a no-op); ``threshold``, glibc's mmap threshold at 64 KiB (``sph.MMAP_THRESHOLD``, B) or at 32 MiB
(glibc's dynamic threshold at its ceiling, A), as in ``speed-scale-memory-alaric/ab_mmap.py``. 3 warm-up steps, then
``ROUNDS`` rounds of ``BLOCK`` steps with each setting (A B, B A, ...). Per step: the calling thread's CPU time
(``time.thread_time``) and minor page faults (``getrusage``); the median of the rounds' ratios B / A. Neither change
alters the arithmetic (the trajectories are the same bit for bit).

    python reproductions/speed-scale-memory-2d/ab.py \\
        alaric2d:1e4:8:20:release,bipi2d:1e4:8:20:release,bipi2d:1e4:8:20:threshold,bipi2d:1e5:6:5:threshold \\
        > reproductions/speed-scale-memory-2d/results/ab.json
"""
import ctypes
import json
import os
import resource
import sys
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))


def main(method, n, rounds, block, what):
    import numba
    import numpy as np

    import bench_scale as B
    from ase_sphrelax import sph

    warnings.simplefilter("ignore")
    numba.set_num_threads(1)
    libc = ctypes.CDLL(None)
    released = sph.release_pair_buffers

    def keep(nlist):
        return None

    settings = dict(A=dict(threshold=32 * 2**20, release=keep), B=dict(threshold=64 * 1024, release=released))
    dim = B.DIM[method]
    if method.startswith("alaric"):
        from ase_sphrelax.build import fill

        domain = B._alaric_domain(dim, n)
        atoms = fill(domain, 1.0, jitter=0.1, seed=0)
        dyn = B.alaric_dynamics(atoms, dim, domain)
        dyn.run(3)

        def work():
            dyn.run(block)
    elif method.startswith("bipi"):
        from ase_sphrelax import BIPICalculator, BIPIPacker

        seg, dx, atoms = B._bipi_scene(dim, n)
        packer = BIPIPacker(atoms, BIPICalculator.from_paper(2.0, dx, seg), stages=("2b", "2c"),
                            max_steps_2c=10**9, window=10**9)
        steps = packer.irun()
        for _ in range(3):
            next(steps)

        def work():
            for _ in range(block):
                next(steps)
    else:
        raise SystemExit(f"METHOD must be alaric2d or bipi2d, got {method!r}")
    cpu, faults = dict(A=[], B=[]), dict(A=[], B=[])
    for r in range(rounds):
        for k in ("AB" if r % 2 == 0 else "BA"):
            if what == "threshold":
                libc.mallopt(-3, settings[k]["threshold"])  # M_MMAP_THRESHOLD
            else:
                sph.release_pair_buffers = settings[k]["release"]
            f0 = resource.getrusage(resource.RUSAGE_THREAD).ru_minflt
            t = time.thread_time()
            work()
            cpu[k].append((time.thread_time() - t) / block)
            faults[k].append((resource.getrusage(resource.RUSAGE_THREAD).ru_minflt - f0) / block)
    sph.release_pair_buffers = released
    ratios = [b / a for a, b in zip(cpu["A"], cpu["B"])]
    return dict(method=method, n=n, n_particles=len(atoms), what=what, rounds=rounds, block=block, cpu_per_step=cpu,
                ratios=ratios, ratio_B_over_A=float(np.median(ratios)), minor_faults_per_step=faults)


if __name__ == "__main__":
    from _provenance import git_version

    if sys.argv[1:] and not sys.argv[1].startswith("-"):
        load = os.getloadavg()
        rows = []
        for spec in sys.argv[1].split(","):
            method, n, rounds, block, what = spec.split(":")
            if what not in ("release", "threshold"):
                raise SystemExit(f"WHAT must be release or threshold, got {what!r}")
            rows.append(main(method, float(n), int(rounds), int(block), what))
        print(json.dumps(dict(version=git_version(), command=" ".join(["python", *sys.argv]), load_start=load,
                              load_end=os.getloadavg(), threads=1, rows=rows), indent=1))
    else:
        raise SystemExit(__doc__)
