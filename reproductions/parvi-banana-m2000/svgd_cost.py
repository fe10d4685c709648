"""Where SVGD's time goes at M = 2000 (issue 18, item 5): one step's parts, and a whole step with the median
heuristic of before 2026-12-02 (an M x M x d difference array and its lower triangle) against the one of
:func:`ase_sphrelax.sampling.baselines.median_length_scale` now (scipy's pdist; the same median to the bit),
interleaved rounds, medians. Writes ``svgd_cost.json`` next to this file.

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 PYTHONPATH=. nice -n 10 .venv/bin/python \
        reproductions/parvi-banana-m2000/svgd_cost.py
"""
import json
import os
import subprocess
import time
from pathlib import Path

import numpy as np

from ase_sphrelax.sampling import baselines, get_target


def median_length_scale_before(x_pc, median_points=2000, seed=0):
    """The median heuristic as it was before 2026-12-02 (copied from git 2b5819a's baselines.py)."""
    m = x_pc.shape[0]
    sub = x_pc
    if m > median_points:
        sub = x_pc[np.random.default_rng(seed).choice(m, median_points, replace=False)]
    diff = sub[:, None, :] - sub[None, :, :]
    r = np.sqrt(np.einsum("abc,abc->ab", diff, diff))[np.tril_indices(sub.shape[0], k=-1)]
    return float(np.median(r) ** 2 / np.log(m))


def main(m=2000, rounds=7):
    target = get_target("banana")
    x = np.random.default_rng(0).standard_normal((m, 2))
    g = target.score(x)
    ell = baselines.median_length_scale(x)
    parts = dict(median_before=lambda: median_length_scale_before(x), median_now=lambda: baselines.median_length_scale(x),
                 direction=lambda: baselines.svgd_direction(x, g, ell), score=lambda: target.score(x))
    times = {k: [] for k in parts}
    for _ in range(rounds):
        for name, f in parts.items():
            t0 = time.perf_counter()
            f()
            times[name].append(time.perf_counter() - t0)
    med = {k: float(np.median(v)) for k, v in times.items()}
    same = median_length_scale_before(x) == baselines.median_length_scale(x)
    step_before = med["median_before"] + med["direction"] + med["score"]
    step_now = med["median_now"] + med["direction"] + med["score"]
    out = dict(m=m, rounds=rounds, seconds_median=med, seconds_all=times, same_median_bitwise=same,
               step_before=step_before, step_now=step_now, median_share_before=med["median_before"] / step_before,
               speedup=step_before / step_now, steps_1000_before_min=1000 * step_before / 60,
               steps_1000_now_min=1000 * step_now / 60, load_average=os.getloadavg(),
               git=subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip())
    (Path(__file__).resolve().parent / "results" / "svgd_cost.json").write_text(json.dumps(out, indent=1))
    print(json.dumps({k: v for k, v in out.items() if k != "seconds_all"}, indent=1))


if __name__ == "__main__":
    main()
