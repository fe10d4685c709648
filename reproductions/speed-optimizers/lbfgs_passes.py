"""Why SPHLBFGS's 2D step at 1e6 stays above 1.25 force evaluations: the time of its three passes over the
coordinates, alone, at several history lengths.

The question, declared before the runs: with the force evaluation of Fan's 2D circle at 1e6 taking what the
timing scan measured inside its runs (``results/lbfgs_memory_2d_1e6_m*.json``, ``times.sph_in_calculator``, the
median over all their rounds), how much of a step do SPHLBFGS's own passes take, at each history length?

* the passes of :class:`ase_sphrelax.drivers.sph_optimizers.SPHLBFGS` (``_lbfgs_pair_dots``, ``_lbfgs_combine``,
  ``_lbfgs_finish``, on the package's threads) on random arrays of the scene's size (``dim * N`` coordinates,
  ``memory`` pairs), the best of ``--repeat`` calls each;
* the bytes each pass reads and writes (x and F are float64 ``(N, 3)`` arrays of which the passes touch every row),
  and the rate that makes;
* ``floor_ratio``: 1 + (the three passes) / (the evaluation inside the scan's runs): the least step / evaluation an
  LBFGS step of that history can have here, before any Python between the passes;
* the same passes with the history stored in float32 (``history_dtype``; timing only: SPHLBFGS keeps float64, and
  its pending pair ``s = -x_k + x_{k+1}`` would lose its digits in float32), the least a half-size history could
  save;
* the same passes compiled with ``fastmath`` (``compiled``: "fastmath"; the sums reassociated, so that the compiler may
  vectorise the dot products; timing only), the least a reordering of the sums could save.

    NUMBA_NUM_THREADS=2 python reproductions/speed-optimizers/lbfgs_passes.py \
        --out reproductions/speed-optimizers/results/lbfgs_passes_2d_1e6.json
"""
import argparse
import json
import statistics
import sys
import time
from pathlib import Path

import numba
import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))

from _provenance import git_version, machine, write_json  # noqa: E402

from ase_sphrelax.drivers import sph_optimizers as so  # noqa: E402
from ase_sphrelax.parallel import reduce_chunks, run_chunks  # noqa: E402

HERE = Path(__file__).resolve().parent
PASSES = {"strict": (so._lbfgs_pair_dots, so._lbfgs_combine, so._lbfgs_finish),  # the package's, as compiled there
          "fastmath": tuple(numba.njit(nogil=True, fastmath=True)(k.py_func)
                            for k in (so._lbfgs_pair_dots, so._lbfgs_combine, so._lbfgs_finish))}


def best_ms(call, repeat):
    call()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        call()
        times.append(time.perf_counter() - t0)
    return 1e3 * min(times)


def evaluation_ms(memories):
    """The force evaluation inside the timing scan's SPHLBFGS runs (``times.sph_in_calculator``): the median over
    every round of the scans of these histories, and N."""
    rounds, n = [], None
    for memory in memories:
        rec = json.loads((HERE / "results" / f"lbfgs_memory_2d_1e6_m{memory}.json").read_text())
        row = next(r for r in rec["timing"] if r["name"] == "lbfgs" and r["dim"] == 2)
        rounds += row["times"]["sph_in_calculator"]
        n = row["n"]
    return 1e3 * statistics.median(rounds), n


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--memories", default="1,2,3,5")
    parser.add_argument("--repeat", type=int, default=7)
    parser.add_argument("--out", default=str(HERE / "results" / "lbfgs_passes_2d_1e6.json"))
    args = parser.parse_args(argv)
    d = 2
    rng = np.random.default_rng(0)
    rows = []
    memories = [int(m) for m in args.memories.split(",")]
    evaluation, n = evaluation_ms(memories)
    cases = [(m, t, c) for c in PASSES for t in ("float64", "float32") for m in memories]
    for memory, dtype, compiled in cases:
        dots, combine, finish = PASSES[compiled]
        s, y = rng.random((memory, n, d)).astype(dtype), rng.random((memory, n, d)).astype(dtype)
        x, f, new = rng.random((n, 3)), rng.random((n, 3)), np.empty((n, 3))
        cs, cy = rng.random(memory), rng.random(memory)
        slot = memory - 1
        vec, rows3 = s.itemsize * n * d, 8 * n * 3  # bytes of one history vector, of one (N, 3) array
        passes = {
            "dots": (best_ms(lambda: reduce_chunks(dots, n, (s, y, slot, x, f, d), 6 * memory),
                             args.repeat), 2 * memory * vec + 2 * rows3 + 2 * vec),
            "combine": (best_ms(lambda: reduce_chunks(combine, n, (f, s, y, slot, cs, cy, 0.3, d), 1),
                                args.repeat), 2 * memory * vec + rows3 + vec),
            "finish": (best_ms(lambda: run_chunks(finish, n, (x, f, s[slot], y[slot], 0.5, True, 1.0, d,
                                                                        new, False)), args.repeat),
                       vec + 2 * rows3 + 2 * vec + rows3),
        }
        total = sum(ms for ms, _ in passes.values())
        rows.append(dict(memory=memory, history_dtype=dtype, compiled=compiled, n=n, dim=d, evaluation_ms=evaluation,
                         passes_ms={k: ms for k, (ms, _) in passes.items()},
                         passes_bytes={k: b for k, (_, b) in passes.items()},
                         passes_gb_per_s={k: b / ms / 1e6 for k, (ms, b) in passes.items()},
                         passes_total_ms=total,
                         floor_ratio=1.0 + total / evaluation))
        parts = ", ".join(f"{k} {ms:.1f}" for k, (ms, _) in passes.items())
        print(f"memory {memory} {dtype} {compiled}: passes {total:.1f} ms ({parts}), evaluation {evaluation:.1f} ms: "
              f"floor {1 + total / evaluation:.2f}")
    write_json(args.out, dict(rows=rows, threads=numba.get_num_threads(), machine=machine(),
                              version=git_version(), command="NUMBA_NUM_THREADS=2 python "
                              "reproductions/speed-optimizers/lbfgs_passes.py --out " + str(args.out)))


if __name__ == "__main__":
    main()
