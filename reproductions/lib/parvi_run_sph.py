"""SPH-ParVI alone at M = 2000 (issue 18, item 1): controlled runs of named variants and step counts.

The set-up of ``benchmarks/bench_sampling.py`` (its ``comparison_set``): starts N(0, I) drawn with the seed, reference 20000 i.i.d. points
(seed 10000), 5000 of them (seed 1) for the energy distance, i.i.d. floor of M points drawn with seed + 500. Each
variant is a :func:`ase_sphrelax.sampling.sampler.variant_options` name; ``--steps`` is the budget in score
evaluations per particle, so a variant with ``score_every=K`` runs ``K`` times as many SPH steps, and one with
``score_every=adaptive`` runs until that many evaluations per particle are spent (the sampler's own rule). Rows (one per run) are appended to
``--out`` as runs finish; ``evaluations_per_particle`` is the run's score + density evaluations over M.

    OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 PYTHONPATH=. nice -n 10 .venv/bin/python \
        reproductions/lib/parvi_run_sph.py --targets banana funnel --steps 1000 --seeds 0 \
        --variants local+critical+score_every=adaptive --out reproductions/parvi-adaptive-hold/results/adaptive.json

Every run passes :data:`lib.parvi_pinned.CLASSIC` under the variant's options: the sampler defaults the stored
results were made with (``reproductions/parvi-adaptive-hold``, ``parvi-banana-m2000``, ``parvi-rest-vs-time``).
"""
import argparse
import json
import os
import subprocess
import sys
import time
import warnings
from pathlib import Path

from ase_sphrelax.sampling import get_target, metrics
from ase_sphrelax.sampling.sampler import ParVIDivergence, ParVISampler, variant_options

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
from bench_sampling import comparison_set  # noqa: E402  (the benchmark's reference, i.i.d. floor and starts)

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from lib.parvi_pinned import classic  # noqa: E402  (the sampler defaults the results were made with)


def sph_steps_per_evaluation(options):
    """``steps`` of ParVISampler per score evaluation: K for ``score_every=K``, 1 for ``"adaptive"`` (its
    ``steps`` is already the evaluation budget) and for the default."""
    every = options.get("score_every", 1)
    return 1 if every == "adaptive" else every


def build_sampler(target, variant, m, x0, steps, seed, **extra):
    """The ParVISampler of one row: ``variant``'s options (and ``extra`` keyword options), ``steps`` score
    evaluations per particle."""
    options = classic(**dict(variant_options(variant), **extra))
    return ParVISampler(target.log_density, target.score, **dict(
        options, dim=target.dim, n=m, x0=x0, steps=steps * sph_steps_per_evaluation(options), seed=seed))


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--targets", nargs="+", default=["banana"])
    parser.add_argument("--variants", nargs="+", default=["local+critical"])
    parser.add_argument("--seeds", nargs="+", type=int, default=[0])
    parser.add_argument("--m", type=int, default=2000)
    parser.add_argument("--steps", nargs="+", type=int, default=[1000])
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    rows = json.loads(args.out.read_text())["rows"] if args.out.exists() else []
    git = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    dirty = bool(subprocess.run(["git", "status", "--porcelain", "ase_sphrelax"], capture_output=True,
                                text=True).stdout.strip())
    for seed in args.seeds:
        for tname in args.targets:
            target = get_target(tname)
            ref, iid, x0 = comparison_set(target, args.m, seed)
            for steps in args.steps:
                for variant in args.variants:
                    row = dict(target=tname, m=args.m, steps=steps, seed=seed, variant=variant, iid_energy=iid,
                               git=git + ("+dirty" if dirty else ""), load=os.getloadavg()[0])
                    t0 = time.perf_counter()
                    try:
                        with warnings.catch_warnings():
                            warnings.simplefilter("ignore")
                            res = build_sampler(target, variant, args.m, x0, steps, seed).run()
                    except ParVIDivergence as exc:
                        row.update(error=str(exc)[:200], wall=time.perf_counter() - t0)
                    else:
                        energy = metrics.energy_distance(res.samples, ref)
                        row.update(energy=energy, ratio_to_iid=energy / iid, wall=time.perf_counter() - t0,
                                   evaluations_per_particle=res.evaluations / args.m,
                                   sim_time_median=float(res.trace["time"][-1]), dt_median=res.info["dt_median"],
                                   converged=res.info["converged"],
                                   sph_steps=res.info["steps"], n_score_per_particle=res.n_score / args.m,
                                   coarse=res.info.get("coarse"))
                        if "hold_moved_share" in res.info:
                            row.update(hold_moved_share=res.info["hold_moved_share"])
                    rows.append(row)
                    print(json.dumps(row), flush=True)
                    args.out.write_text(json.dumps(dict(command="see run_sph.py's docstring", rows=rows), indent=1))


if __name__ == "__main__":
    main()
