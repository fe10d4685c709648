"""Global against local time steps (issue 18, items 1-2): funnel and banana, M = 500, 1000 evaluations per particle.

The set-up of ``benchmarks/bench_sampling.py`` (the README's ``m100_500_full`` run): starts N(0, I) drawn with
the seed, SPH-ParVI with the sampler's default friction, reference 20000 i.i.d. points (seed 10000), 5000 of them
(seed 1) for the energy distance, i.i.d. floor of M points drawn with seed + 500. Writes ``results.json`` (one row
per run, appended as runs finish) next to this file.

    OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 PYTHONPATH=. nice -n 10 .venv/bin/python \
        reproductions/parvi-steps/run.py --seeds 0 1 2
"""
import argparse
import json
import os
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from ase_sphrelax.sampling import get_target, metrics, sampler as sampler_module
from ase_sphrelax.sampling.sampler import ParVIDivergence, ParVISampler

OUT = Path(__file__).resolve().parent / "results" / "results.json"

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
from bench_sampling import comparison_set  # noqa: E402  (the benchmark's reference, i.i.d. floor and starts)
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from lib.parvi_pinned import classic  # noqa: E402  (the sampler defaults the results were made with)


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--targets", nargs="+", default=["funnel", "banana"])
    parser.add_argument("--modes", nargs="+", default=["global", "local"])
    parser.add_argument("--seeds", nargs="+", type=int, default=[0])
    parser.add_argument("--m", type=int, default=500)
    parser.add_argument("--steps", type=int, default=1000)
    parser.add_argument("--courant", type=float, default=None, help="default: the sampler's (0.5 global, 0.25 local)")
    parser.add_argument("--growth", type=float, default=None, help="sampler.LOCAL_GROWTH (default None: off)")
    args = parser.parse_args()
    sampler_module.LOCAL_GROWTH = args.growth
    rows = json.loads(OUT.read_text())["rows"] if OUT.exists() else []
    git = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    for seed in args.seeds:
        for tname in args.targets:
            target = get_target(tname)
            ref, iid, x0 = comparison_set(target, args.m, seed)
            for mode in args.modes:
                row = dict(target=tname, m=args.m, steps=args.steps, seed=seed, time_step=mode, iid_energy=iid,
                           courant=args.courant, growth=args.growth,
                           git=git, load=os.getloadavg()[0])
                t0 = time.perf_counter()
                try:
                    with warnings.catch_warnings():
                        warnings.simplefilter("ignore")
                        res = ParVISampler(target.log_density, target.score, **classic(
                            dim=target.dim, n=args.m, x0=x0, steps=args.steps, seed=seed, time_step=mode,
                            courant=args.courant)).run()
                except ParVIDivergence as exc:
                    row.update(error=str(exc)[:200], wall=time.perf_counter() - t0)
                else:
                    energy = metrics.energy_distance(res.samples, ref)
                    row.update(energy=energy, ratio_to_iid=energy / iid, wall=time.perf_counter() - t0,
                               sim_time_median=float(res.trace["time"][-1]), dt_median=res.info["dt_median"],
                               dt_min=res.info["dt_min"], converged=res.info["converged"],
                               friction=res.info["friction"], courant=res.info["courant"],
                               kinetic_final=float(res.trace["kinetic"][-1]),
                               kinetic_max_last_half=float(np.max(res.trace["kinetic"][len(res.trace["kinetic"]) // 2:])),
                               kinetic_min_last_half=float(np.min(res.trace["kinetic"][len(res.trace["kinetic"]) // 2:])),
                               cov_x1=float(np.var(res.samples[:, 1])))
                rows.append(row)
                print(json.dumps(row), flush=True)
                OUT.write_text(json.dumps(dict(command="see module docstring", rows=rows), indent=1))


if __name__ == "__main__":
    main()
