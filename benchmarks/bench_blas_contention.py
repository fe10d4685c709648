"""ASE optimisers under a competing load: BLAS threads limited in the steps or not (issue 9, item 4).

On Fan's default circle (8224 particles, dx = 1/256, h = 2.6 dx, jitter 0.1, seed 0, as
`sphrelax relax`) it times ``--steps`` steps of

* ``lbfgs limited``: ``make_optimizer("lbfgs", atoms)`` (the default: BLAS on one thread
  inside each step, :mod:`ase_sphrelax.drivers.blas`);
* ``lbfgs unlimited``: the same with ``blas_threads=False`` (OpenBLAS's own thread count);
* ``fire limited`` / ``fire unlimited``;
* ``fan``: Eq. 2.4 (no BLAS work), the reference,

while a competing process keeps one core busy (a Python busy loop started by this
script, ended by it at the end; ``--no-load`` runs without it). Each case is repeated
``--repeats`` times in interleaved rounds from the same initial particles; the median is
reported, with the load average.

    python benchmarks/bench_blas_contention.py [--steps 100] [--repeats 5] [--no-load]

Writes ``benchmarks/results/blas_contention.json``.
"""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

from threadpoolctl import threadpool_info

from ase_sphrelax import FanCalculator
from ase_sphrelax.build import fill
from ase_sphrelax.domains import Circle
from ase_sphrelax.drivers import make_optimizer
from ase_sphrelax.drivers.blas import user_blas_threads

try:
    from _provenance import git_version, write_json
except ImportError:
    from benchmarks._provenance import git_version, write_json

CASES = {
    "fan": dict(name="fan"),
    "lbfgs limited": dict(name="lbfgs"),
    "lbfgs unlimited": dict(name="lbfgs", blas_threads=False),
    "fire limited": dict(name="fire"),
    "fire unlimited": dict(name="fire", blas_threads=False),
}


def circle():
    domain = Circle((0.5, 0.5), 0.2)
    dx = 1 / 256
    return domain, dx, fill(domain, dx, jitter=0.1, seed=0)


def run_case(case, atoms0, domain, dx, steps):
    atoms = atoms0.copy()
    atoms.calc = FanCalculator(h=2.6 * dx, dx=dx, domain=domain, dim=2)
    kwargs = dict(CASES[case])
    opt = make_optimizer(kwargs.pop("name"), atoms, backend="ase", **kwargs)  # ASE's (numpy/BLAS) optimisers
    t0 = time.perf_counter()
    opt.run(fmax=1e-30, steps=steps)
    return time.perf_counter() - t0, atoms.get_potential_energy()


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--steps", type=int, default=100)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--no-load", action="store_true", help="no competing process")
    parser.add_argument("--cases", default=",".join(CASES))
    parser.add_argument("--out", default=str(Path(__file__).parent / "results" / "blas_contention.json"))
    args = parser.parse_args(argv)
    cases = args.cases.split(",")
    domain, dx, atoms0 = circle()
    run_case("fan", atoms0, domain, dx, 2)  # compile / load outside the timings
    blas = [dict(internal_api=lib["internal_api"], num_threads=lib["num_threads"]) for lib in threadpool_info()
            if lib["user_api"] == "blas"]
    competitor = None
    if not args.no_load:
        competitor = subprocess.Popen([sys.executable, "-c", "while True: pass"])
        time.sleep(1.0)
    times = {c: [] for c in cases}
    energies = {}
    load_start = os.getloadavg()
    try:
        for _ in range(args.repeats):
            for case in cases:
                wall, energy = run_case(case, atoms0, domain, dx, args.steps)
                times[case].append(wall)
                energies[case] = energy
                print(f"  {case:16s} {wall:8.3f} s  E {energy:.6e}  load {os.getloadavg()[0]:.2f}", flush=True)
    finally:
        if competitor is not None:
            competitor.kill()
            competitor.wait()
    med = {c: statistics.median(v) for c, v in times.items()}
    result = dict(version=git_version(), started=time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
                  n=len(atoms0), steps=args.steps, repeats=args.repeats, competing_load=not args.no_load,
                  blas=blas, user_blas_setting=user_blas_threads(), load_average_start=load_start,
                  load_average_end=os.getloadavg(), median_s=med, all_s=times, final_energy=energies)
    print(f"N = {len(atoms0)}, {args.steps} steps, median of {args.repeats}, competing load: {not args.no_load}, "
          f"BLAS {blas}, load {load_start[0]:.2f} -> {os.getloadavg()[0]:.2f}")
    for case in cases:
        print(f"{case:16s} {med[case]:8.3f} s  ({1e3 * med[case] / args.steps:.2f} ms/step)")
    write_json(args.out, result)
    return result


if __name__ == "__main__":
    main()
