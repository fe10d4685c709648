"""SPH-ParVI alone at M = 2000 (issue 18, item 1): controlled runs of named variants and step counts.

The set-up of ``benchmarks/bench_sampling.py``: starts N(0, I) drawn with the seed, reference 20000 i.i.d. points
(seed 10000), 5000 of them (seed 1) for the energy distance, i.i.d. floor of M points drawn with seed + 500. Each
variant is a :func:`ase_sphrelax.sampling.sampler.variant_options` name; ``--steps`` is the budget in score
evaluations per particle, so a variant with ``score_every=K`` runs ``K`` times as many SPH steps. Rows (one per run) are appended to
``--out`` as runs finish; ``evaluations_per_particle`` is the run's score + density evaluations over M.

    OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 PYTHONPATH=. nice -n 10 .venv/bin/python \
        reproductions/parvi-banana-m2000/run.py --targets banana --steps 1000 2000 --seeds 0 1 2 \
        --variants local+critical --out reproductions/parvi-banana-m2000/results/steps.json

The runner is ``reproductions/lib/parvi_run_sph.py`` (the same set-up and rows; part 4 added the adaptive hold's
budget rule and its ``hold_moved_share``, written only for runs that report it): this file runs it.
"""
import runpy
from pathlib import Path

if __name__ == "__main__":
    runpy.run_path(str(Path(__file__).resolve().parents[1] / "lib" / "parvi_run_sph.py"), run_name="__main__")
