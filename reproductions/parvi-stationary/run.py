"""The stationary density of each SPH-ParVI formulation, predicted against measured (issue 8, item 4).

Runs ``benchmarks/bench_sampling_theory.py`` (unit Gaussian, 300 particles in 1D, 500 in 2D, run to rest) with the
sampler defaults the stored results were made with (``reproductions/lib/parvi_pinned.py``) and writes
``stationary.json`` and ``stationary.md`` to ``--out`` (~4 min)::

    python reproductions/parvi-stationary/run.py --out reproductions/parvi-stationary/results
"""
import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from lib.parvi_pinned import run_benchmark  # noqa: E402


def main(argv=None):
    parser = argparse.ArgumentParser()
    parser.add_argument("--out", type=Path, default=Path(__file__).resolve().parent / "results")
    args = parser.parse_args(argv)
    run_benchmark("bench_sampling_theory", None, out=args.out)


if __name__ == "__main__":
    main()
