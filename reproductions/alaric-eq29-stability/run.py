"""Eq. 29 (ALARIC's paper form) made stable: one ingredient at a time from the paper form's old setting.

Runs, from the flat start, the paper form ``form="paper"`` (Eq. 29, ``P_eff = c_s^2 (rho - rho*)``) on

* Table 2's Delta = 0.1 and 0.05 rows (1D, Eq. 46, 101 -> 303 particles, one split, no polish: the same run as
  ``sphrelax density --profile eq46 --delta D --dim 1 --n 303 --split 1 --no-polish --form paper``), and
* a 2D uniform target in an ellipse (semi-axes 1 and 0.6, 64-edge polygon, mirror ghosts), 50 -> 200 particles,
* and (``d1``, ``--only d1``) Delta = 1, where the bare Eq. 29 converges below 1e-8: does P_B move the fixed point?

with the old setting of the paper form (eta = 3, no background pressure, Courant factor 0.25, Omega floor 0.05,
viscosity switch alpha in [0, 1], Wendland C4) and with one ingredient changed at a time, then the recipe found
(background pressure + eta = 2.5); the recipe with either ingredient taken out is the ``pb`` or ``eta2.5`` run.

Steps are capped (``--max-steps``, both stages together, 6000 in 1D; ``--max-steps-2d``, 2000 for the ellipse) so
that each run stays under about 2 CPU-minutes on a shared machine: a run stopped by the cap has
``stop_reason = "max_steps"`` and ``converged = false``.

Each run writes ``results/<case>__<variant>.json``: epsilon (Eq. 45), nearest-neighbour distance min / mean
(``nn_ratio``; pairing: below 0.5), steps, stop reason, converged, wall time, and (runs made after the first
three cases: ``d1``) ``deficit_relative``, ``max(rho* - rho)_+ / max rho*`` at the end (``P_B / (c_s^2 max rho*)``). Usage (from the repository root)::

    python reproductions/alaric-eq29-stability/run.py [--out DIR] [--max-steps N] [--only CASE] [--variants a,b]
"""
from __future__ import annotations

import argparse
import json
import time
import warnings
from pathlib import Path

import numpy as np

from ase_sphrelax.drivers.alaric_dynamics import relax_density, start_atoms
from ase_sphrelax.models import alaric as model

HERE = Path(__file__).resolve().parent

# the paper form's setting before this study (main at 2c09a2e): eta = 3 (default_eta of C4), no P_B, C = 0.25,
# Omega floor 0.05, alpha0 = alpha_max = 1, Wendland C4
OLD = dict(calc=dict(eta=3.0, background_pressure=0.0, omega_floor=0.05, kernel="wendland_c4"),
           dyn=dict(cfl=0.25, viscosity=True, alpha0=1.0, alpha_max=1.0))
VARIANTS = {
    "old": {},
    "pb": dict(calc=dict(background_pressure="deficit")),
    "eta2.5": dict(calc=dict(eta=2.5)),
    "eta3.5": dict(calc=dict(eta=3.5)),
    "cfl0.1": dict(dyn=dict(cfl=0.1)),
    "omega0": dict(calc=dict(omega_floor=0.0)),
    "omega0.3": dict(calc=dict(omega_floor=0.3)),
    "visc_off": dict(dyn=dict(viscosity=False)),
    "alpha_max2": dict(dyn=dict(alpha0=2.0, alpha_max=2.0)),
    "kernel_c2": dict(calc=dict(kernel="wendland_c2")),  # eta kept at 3
    "recipe": dict(calc=dict(background_pressure="deficit", eta=2.5)),  # P_B + eta 2.5
}
CASES = ("d0.1", "d0.05", "ellipse2d", "d1")  # d1: Delta = 1, where the bare Eq. 29 converges: the fixed point


def ellipse(a=1.0, b=0.6, k=64):
    from ase_sphrelax.domains.polygon import Polygon

    t = 2 * np.pi * np.arange(k) / k
    return Polygon([np.stack([a * np.cos(t), b * np.sin(t)], axis=1)])


def nn_ratio(atoms, dim):
    """Smallest nearest-neighbour distance over the mean one (1D: on the periodic interval)."""
    if dim == 1:
        x = np.sort(atoms.positions[:, 0] % atoms.cell[0, 0])
        gaps = np.diff(np.concatenate([x, [x[0] + atoms.cell[0, 0]]]))
        nn = np.minimum(gaps, np.roll(gaps, 1))
    else:
        from scipy.spatial import cKDTree

        nn = cKDTree(atoms.positions[:, :dim]).query(atoms.positions[:, :dim], k=2)[0][:, 1]
    return float(nn.min() / nn.mean()), float(nn.min()), float(nn.mean())


def settings(variant):
    calc, dyn = dict(OLD["calc"]), dict(OLD["dyn"])
    calc.update(VARIANTS[variant].get("calc", {}))
    dyn.update(VARIANTS[variant].get("dyn", {}))
    return calc, dyn


def run_one(case, variant, max_steps):
    calc, dyn = settings(variant)
    if case.startswith("d"):
        delta = float(case[1:])
        dim, n0, domain = 1, 101, None
        density, gradient = model.eq46(delta)
    else:
        dim, n0, domain = 2, 50, ellipse()
        density, gradient = model.uniform(1.0)
    atoms, origin, domain = start_atoms(n0, dim, domain=domain, seed=0)
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        error = None
        try:
            res = relax_density(atoms, density, dim, target_gradient=gradient, splits=1, domain=domain,
                                origin=origin, form="paper", polish=False, max_steps=max_steps, seed=0,
                                calculator_options=calc, **dyn)
        except Exception as exc:  # noqa: BLE001 - a run that breaks is a result of the study
            error = f"{type(exc).__name__}: {exc}"
    wall = time.perf_counter() - t0
    out = dict(case=case, variant=variant, calculator=calc, dynamics=dyn, max_steps=max_steps, n=len(atoms),
               wall_time_s=round(wall, 1))
    if error:
        out.update(error=error, converged=False)
        return out
    ratio, nn_min, nn_mean = nn_ratio(res["atoms"], dim)
    r = res["calculator"].results  # the final state (Eq. 44 mass): the largest deficit, P_B / c_s^2 of "deficit"
    out["deficit_relative"] = max(float(np.max(r["target"] - r["density"])), 0.0) / float(np.max(r["target"]))
    out.update(epsilon=res["epsilon"], nn_ratio=ratio, nn_min=nn_min, nn_mean=nn_mean, steps=int(res["steps"]),
               stop_reason=res["stop_reason"], converged=bool(res["converged"]),
               paired=bool(ratio < 0.5), max_relative_error=res["diagnostics"]["max_relative_error"])
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(HERE / "results"))
    ap.add_argument("--max-steps", type=int, default=6000,
                    help="step cap per run, both stages (default 6000: about 2 CPU-min per run at most)")
    ap.add_argument("--max-steps-2d", type=int, default=2000, help="step cap of the ellipse runs (default 2000)")
    ap.add_argument("--only", choices=CASES, action="append")
    ap.add_argument("--variants", default=",".join(VARIANTS))
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    for case in args.only or CASES:
        for variant in args.variants.split(","):
            r = run_one(case, variant, args.max_steps_2d if case == "ellipse2d" else args.max_steps)
            (out / f"{case}__{variant}.json").write_text(json.dumps(r, indent=1) + "\n")
            print(f"{case:10s} {variant:11s} eps={r.get('epsilon', float('nan')):.2e} "
                  f"nn={r.get('nn_ratio', float('nan')):.3f} steps={r.get('steps')} {r.get('stop_reason')} "
                  f"{r['wall_time_s']}s {r.get('error', '')}", flush=True)


if __name__ == "__main__":
    main()
