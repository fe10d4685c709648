"""What the stored list saves in time: ALARIC steps with ``store_list=True`` and ``False``, interleaved in one process.

bench_scale.py's ALARIC scene (disc / ball of N particles at unit spacing, uniform target, mirror ghosts, S+F+V), two
dynamics from the same start, two warm-up steps each, then ``ROUNDS`` rounds of one step each (A B, B A, ...) on one
numba thread; the CPU time (``time.process_time``) of every step and the median ratio scan / list.

    python reproductions/speed-scale-memory-alaric/ab_list.py alaric3d 1e5 6 \
        > reproductions/speed-scale-memory-alaric/results/ab_list_3d_1e5.json
"""
import json
import os
import sys
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))


def main(method, n, rounds):
    import numba
    import numpy as np

    import bench_scale as B
    from _provenance import git_version
    from ase_sphrelax import ALARICCalculator
    from ase_sphrelax.build import fill
    from ase_sphrelax.drivers.alaric_dynamics import ALARICDynamics
    from ase_sphrelax.models.alaric import resolve_boundary

    warnings.simplefilter("ignore")
    numba.set_num_threads(1)
    dim = B.DIM[method]
    domain = B._alaric_domain(dim, n)
    dyns = {}
    for store in (True, False):
        atoms = fill(domain, 1.0, jitter=0.1, seed=0)
        atoms.calc = ALARICCalculator(target_density=B._uniform, target_gradient=B._no_gradient, dim=dim,
                                      domain=domain, boundary=resolve_boundary("auto", domain), store_list=store)
        dyns[store] = ALARICDynamics(atoms, eps_min=0.0, eps_dot_min=0.0)
        dyns[store].run(2)
    cpu = {True: [], False: []}
    for r in range(rounds):
        for store in ((True, False) if r % 2 == 0 else (False, True)):
            c = time.process_time()
            dyns[store].run(1)
            cpu[store].append(time.process_time() - c)
    return dict(version=git_version(), load=os.getloadavg(), method=method, n=len(dyns[True].atoms), rounds=rounds,
                cpu_list=cpu[True], cpu_scan=cpu[False], median_list=float(np.median(cpu[True])),
                median_scan=float(np.median(cpu[False])),
                ratio_scan_over_list=float(np.median(cpu[False]) / np.median(cpu[True])),
                list_builds=dyns[True].atoms.calc.nlist.builds, steps_each=2 + rounds)


if __name__ == "__main__":
    print(json.dumps(main(sys.argv[1], float(sys.argv[2]), int(sys.argv[3])), indent=1))
