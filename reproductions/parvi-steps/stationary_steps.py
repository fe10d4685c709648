"""Stationary density with global and local time steps (theory.py, L2): unit Gaussian, isothermal, alpha = c0^2 and 2 c0^2.

The set-up of tests/test_parvi_steps.py (and of ``stationary.md``'s isothermal rows): 300 particles in 1D (3000
steps), 500 in 2D (1200 steps), seed 1. Writes ``stationary_steps.json`` next to this file.

    OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 PYTHONPATH=. nice -n 10 .venv/bin/python \
        reproductions/parvi-steps/stationary_steps.py
"""
import json
import os
from pathlib import Path

import numpy as np

from ase_sphrelax.sampling.sampler import ParVISampler
from ase_sphrelax.sampling.targets import gaussian_target
from ase_sphrelax.sampling.theory import predicted_gaussian_moments

import sys  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from lib.parvi_pinned import classic  # noqa: E402  (the sampler defaults the results were made with)


def kurtosis(x):
    x = x - x.mean(axis=0)
    return float(np.mean((x**4).mean(axis=0) / (x**2).mean(axis=0) ** 2))


rows = []
for dim, n, steps in ((1, 300, 3000), (2, 500, 1200)):
    target = gaussian_target(np.zeros(dim), np.eye(dim))
    for alpha in (1.0, 2.0):
        predicted = predicted_gaussian_moments("force", "isothermal", dim, alpha=alpha, c0=1.0)
        for mode in ("global", "local"):
            res = ParVISampler(target.log_density, target.score, **classic(
                dim=dim, n=n, alpha=alpha, c0=1.0, steps=steps, seed=1, time_step=mode)).run()
            row = dict(dim=dim, n=n, steps=steps, alpha=alpha, time_step=mode,
                       predicted_variance=predicted["variance"], variance=float(res.samples.var(axis=0).mean()),
                       predicted_kurtosis=3.0, kurtosis=kurtosis(res.samples), converged=res.info["converged"],
                       dt_median=res.info["dt_median"], dt_min=res.info["dt_min"],
                       sim_time_median=float(res.trace["time"][-1]), load=os.getloadavg()[0])
            rows.append(row)
            print(json.dumps(row), flush=True)
(Path(__file__).resolve().parent / "results" / "stationary_steps.json").write_text(json.dumps(dict(rows=rows), indent=1))
