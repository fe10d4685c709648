"""Where the coarse-to-fine error comes from (issue 18, item 1): banana and funnel at M = 2000, one seed.

Runs the two levels of ``coarse_to_fine=4`` by hand (the sampler's own pieces) and measures the energy distance over
i.i.d. (2000 points, seed + 500; the coarse level also over i.i.d. of its own size) of: the coarse level's final
state, the children right after the split, and the fine level after ``--fine-steps`` steps from the same children.
Rows appended to ``diagnose_coarse.json``.

    OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 PYTHONPATH=. nice -n 10 .venv/bin/python \
        reproductions/parvi-banana-m2000/diagnose_coarse.py --targets banana funnel --seeds 1
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

from ase_sphrelax.sampling import get_target, metrics
from ase_sphrelax.sampling.coarse_to_fine import child_counts, split_into_children
from ase_sphrelax.sampling.sampler import ParVISampler, variant_options

OUT = Path(__file__).resolve().parent / "results" / "diagnose_coarse.json"

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
from bench_sampling import comparison_set  # noqa: E402  (the benchmark's reference, i.i.d. floor and starts)
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from lib.parvi_pinned import classic  # noqa: E402  (the sampler defaults the results were made with)


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--targets", nargs="+", default=["banana", "funnel"])
    parser.add_argument("--seeds", nargs="+", type=int, default=[1])
    parser.add_argument("--variant", default="local+critical")
    parser.add_argument("--factor", type=int, default=4)
    parser.add_argument("--coarse-steps", type=int, default=2000)
    parser.add_argument("--fine-steps", nargs="+", type=int, default=[500, 1000, 2000])
    parser.add_argument("--m", type=int, default=2000)
    args = parser.parse_args()
    rows = json.loads(OUT.read_text())["rows"] if OUT.exists() else []
    git = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    options = variant_options(args.variant)
    warnings.simplefilter("ignore")
    for seed in args.seeds:
        for tname in args.targets:
            target = get_target(tname)
            ref, iid, x0 = comparison_set(target, args.m, seed)
            n_c = args.m // args.factor
            iid_c = metrics.energy_distance(target.sample(n_c, np.random.default_rng(seed + 500)), ref)
            t0 = time.perf_counter()
            coarse = ParVISampler(target.log_density, target.score, **classic(
                dim=2, n=n_c, x0=x0[:n_c], steps=args.coarse_steps, seed=seed, **options))
            res_c = coarse.run()
            r_pc, ev = coarse.final_state
            children = split_into_children(r_pc, np.broadcast_to(ev.mass / ev.rho, (n_c,)), child_counts(args.m, n_c),
                                           seed=seed)
            row = dict(target=tname, seed=seed, m=args.m, variant=args.variant, factor=args.factor,
                       coarse_steps=args.coarse_steps, git=git, load=os.getloadavg()[0], iid_energy=iid,
                       iid_energy_coarse_size=iid_c,
                       coarse_over_iid_own_size=metrics.energy_distance(res_c.samples, ref) / iid_c,
                       coarse_over_iid_m=metrics.energy_distance(res_c.samples, ref) / iid,
                       children_over_iid=metrics.energy_distance(children, ref) / iid,
                       coarse_time=float(res_c.trace["time"][-1]), coarse_wall=time.perf_counter() - t0, fine={})
            for steps in args.fine_steps:
                res = ParVISampler(target.log_density, target.score, **classic(
                    dim=2, n=args.m, x0=children, steps=steps, seed=seed, **options)).run()
                row["fine"][steps] = dict(over_iid=metrics.energy_distance(res.samples, ref) / iid,
                                          time=float(res.trace["time"][-1]), converged=res.info["converged"])
                print(tname, seed, steps, row["fine"][steps], flush=True)
            rows.append(row)
            print(json.dumps(row), flush=True)
            OUT.write_text(json.dumps(dict(command="see diagnose_coarse.py's docstring", rows=rows), indent=1))


if __name__ == "__main__":
    main()
