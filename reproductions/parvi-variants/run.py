"""SPH-ParVI variants, one ingredient at a time (issue 18, item 1): M = 500, 1000 evaluations per particle.

The set-up of ``benchmarks/bench_sampling.py`` and ``reproductions/parvi-steps/run.py``: starts N(0, I) drawn with the seed,
reference 20000 i.i.d. points (seed 10000), 5000 of them (seed 1) for the energy distance, i.i.d. floor of M points
drawn with seed + 500. A variant is a name of :func:`ase_sphrelax.sampling.sampler.variant_options`
(``default``, ``whiten``, ``local``, ``critical``, ``friction=0.3``, joined by ``+``). Appends one row per run to
``--out`` (default ``results/results.json`` next to this file) as runs finish; ``summarize.py`` writes ``summary.md``.

    OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 PYTHONPATH=. nice -n 10 .venv/bin/python \\
        reproductions/parvi-variants/run.py --seeds 0 1 2 --variants default whiten local critical
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
from ase_sphrelax.sampling.sampler import ParVIDivergence, ParVISampler, variant_options

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parents[1] / "benchmarks"))
from bench_sampling import comparison_set  # noqa: E402  (the benchmark's reference, i.i.d. floor and starts)
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from lib.parvi_pinned import classic  # noqa: E402  (the sampler defaults the results were made with)


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--targets", nargs="+", default=["banana", "funnel", "correlated"])
    parser.add_argument("--variants", nargs="+", default=["default"])
    parser.add_argument("--seeds", nargs="+", type=int, default=[0])
    parser.add_argument("--m", type=int, default=500)
    parser.add_argument("--steps", type=int, default=1000)
    parser.add_argument("--out", type=Path, default=HERE / "results" / "results.json")
    parser.add_argument("--tag", default="", help="a label stored in every row (which experiment)")
    args = parser.parse_args()
    options = {v: variant_options(v) for v in args.variants}  # bad names fail before any run
    rows = json.loads(args.out.read_text())["rows"] if args.out.exists() else []
    git = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    dirty = bool(subprocess.run(["git", "status", "--porcelain", "ase_sphrelax"], capture_output=True,
                                text=True).stdout.strip())
    for seed in args.seeds:
        for tname in args.targets:
            target = get_target(tname)
            ref, iid, x0 = comparison_set(target, args.m, seed, HERE / "results")
            for variant in args.variants:
                row = dict(target=tname, m=args.m, steps=args.steps, seed=seed, variant=variant, tag=args.tag,
                           iid_energy=iid, git=git + ("+dirty" if dirty else ""), load=os.getloadavg()[0])
                t0 = time.perf_counter()
                try:
                    with warnings.catch_warnings():
                        warnings.simplefilter("ignore")
                        res = ParVISampler(target.log_density, target.score, **classic(
                            dim=target.dim, n=args.m, x0=x0, steps=args.steps, seed=seed, **options[variant])).run()
                except ParVIDivergence as exc:
                    row.update(error=str(exc)[:200], wall=time.perf_counter() - t0)
                else:
                    energy = metrics.energy_distance(res.samples, ref)
                    kinetic = res.trace["kinetic"]
                    friction = res.info["friction"]
                    row.update(energy=energy, ratio_to_iid=energy / iid, wall=time.perf_counter() - t0,
                               sim_time_median=float(res.trace["time"][-1]), dt_median=res.info["dt_median"],
                               dt_min=res.info["dt_min"], converged=res.info["converged"],
                               friction=friction if isinstance(friction, (int, float, str)) else str(friction),
                               friction_rates=res.info.get("friction_rates"),
                               kinetic_final=float(kinetic[-1]),
                               kinetic_max_last_half=float(np.max(kinetic[len(kinetic) // 2:])),
                               var=np.var(res.samples, axis=0).tolist())
                rows.append(row)
                print(json.dumps(row), flush=True)
                args.out.write_text(json.dumps(dict(command="see module docstring", rows=rows), indent=1))


if __name__ == "__main__":
    main()
