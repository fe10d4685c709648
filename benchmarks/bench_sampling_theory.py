"""The stationary density of SPH-ParVI, predicted and measured (issue 8, item 4).

    .venv/bin/python benchmarks/bench_sampling_theory.py

For the unit Gaussian target in 1D (300 particles) and 2D (500 particles), every formulation and EOS is
run to rest and the particles' per-component variance and kurtosis are compared with the hydrostatic
prediction of :mod:`ase_sphrelax.sampling.theory`. Writes ``reproductions/parvi-stationary/results/stationary.md`` and
``stationary.json``.
"""
from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _provenance import git_version  # noqa: E402

from ase_sphrelax.sampling.sampler import ParVIDivergence, ParVISampler  # noqa: E402
from ase_sphrelax.sampling.targets import gaussian_target  # noqa: E402
from ase_sphrelax.sampling.theory import predicted_gaussian_moments  # noqa: E402

OUT = Path(__file__).resolve().parent.parent / "reproductions" / "parvi-stationary" / "results"

# (label, formulation, eos, sampler options by dimension); rho0 given explicitly where it matters
CASES = [
    ("isothermal, alpha = c0^2 (default)", "force", "isothermal", {1: dict(steps=3000), 2: dict(steps=1500)}, {}),
    ("isothermal, alpha = 2 c0^2", "force", "isothermal", {1: dict(steps=3000), 2: dict(steps=1500)},
     dict(alpha=2.0, c0=1.0)),
    ("Tait gamma 7, rho0 = 1 (1D) / 0.5 (2D)", "force", "tait",
     {1: dict(h=0.05, friction=2.0, steps=6000), 2: dict(h=0.25, friction=2.0, steps=6000)}, dict(rho0=None)),
    ("pressure -alpha log(p + eps), isothermal", "pressure-log", "isothermal",
     {1: dict(steps=3000), 2: dict(steps=1500)}, {}),
    ("pressure 1/(alpha (p + eps)), isothermal", "pressure-inverse", "isothermal",
     {1: dict(steps=3000), 2: dict(steps=1500)}, {}),
]


def kurtosis(x):
    x = x - x.mean(axis=0)
    return float(np.mean((x**4).mean(axis=0) / (x**2).mean(axis=0) ** 2))


def main():
    print(f"load average {os.getloadavg()}")
    rows = []
    for label, formulation, eos, options, physics in CASES:
        for dim, n in ((1, 300), (2, 500)):
            target = gaussian_target(np.zeros(dim), np.eye(dim))
            phys = dict(physics)
            if "rho0" in phys:
                phys["rho0"] = 1.0 if dim == 1 else 0.5
            theory = {k: v for k, v in phys.items() if k in ("alpha", "c0", "rho0")}
            predicted = predicted_gaussian_moments(formulation, eos, dim, **theory)
            row = dict(case=label, dim=dim, n=n, predicted_variance=predicted["variance"],
                       predicted_kurtosis=predicted["kurtosis"])
            t0 = time.perf_counter()
            try:
                res = ParVISampler(target.log_density, target.score, dim=dim, n=n, formulation=formulation, eos=eos,
                                   seed=1, courant=0.5, **phys, **options[dim]).run()
                row.update(variance=float(res.samples.var(axis=0).mean()), kurtosis=kurtosis(res.samples),
                           kinetic=float(res.trace["kinetic"][-1]), steps=res.info["steps"])
            except (ParVIDivergence, ValueError) as exc:
                row["error"] = str(exc).splitlines()[0]
            row["wall"] = time.perf_counter() - t0
            rows.append(row)
            print(row, flush=True)
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "stationary.json").write_text(json.dumps(dict(git=git_version(), load_average=os.getloadavg(), rows=rows),
                                                    indent=1))
    lines = ["# Stationary density of SPH-ParVI: predicted against measured", "",
             f"`benchmarks/bench_sampling_theory.py` (git {git_version()}). Unit Gaussian target, 300 particles (1D) "
             "and 500 (2D), run to rest (kinetic energy in the last column); prediction from the hydrostatic "
             "balance of `ase_sphrelax.sampling.theory`.", "",
             "| case | d | predicted variance | measured | ratio | predicted kurtosis | measured | final kinetic |",
             "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for r in rows:
        if "error" in r:
            lines.append(f"| {r['case']} | {r['dim']} | {r['predicted_variance']:.4g} | diverged: {r['error'][:60]} "
                         f"| | {r['predicted_kurtosis']:.3g} | | |")
        else:
            lines.append(f"| {r['case']} | {r['dim']} | {r['predicted_variance']:.4g} | {r['variance']:.4g} | "
                         f"{r['variance'] / r['predicted_variance']:.3f} | {r['predicted_kurtosis']:.3g} | "
                         f"{r['kurtosis']:.3g} | {r['kinetic']:.2g} |")
    (OUT / "stationary.md").write_text("\n".join(lines) + "\n")
    print(f"wrote {OUT / 'stationary.md'}")


if __name__ == "__main__":
    main()
