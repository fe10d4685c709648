"""Why the paper's Eq. 29 form is noisy: one ingredient changed at a time (issue 20 item 2).

Eq. 46 with Delta = 0.1 on the periodic interval [-1, 1), N particles from the equispaced start, ALARIC's
dynamics (S+F+V, chi = 2, theta = 0.1, Eq. 44 mass reset) for a fixed number of steps. The baseline is
``form="paper"`` with its default Omega floor (0.05) and CFL number 0.25; each variant changes one thing:

* ``omega_floor=0``: the exact Omega in the paper form's forces;
* ``cfl=0.1``: a smaller time step;
* ``viscosity=False``: no artificial viscosity (the alpha switch off);
* ``form="log"``: the conservative log potential, whose pressure c_s^2 rho is never negative (no tensile
  instability): the reference for the sign change of P.

Recorded per run: the stop reason and steps, the final and lowest epsilon, the spread of log10 epsilon over
the last half of the checks (noise), the fraction of particles with P_eff = c_s^2 (rho - rho*) < 0 at the
end, the smallest gap over the mean gap, and the wall time.

    python reproductions/lib/alaric_paper_form_experiments.py --n 101 --steps 3000 --out reproductions/alaric-paper-form/results

``--set background``: the least-squares form and Eq. 29 with a background pressure ``beta c_s^2 rho`` instead.
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
from ase import Atoms

from ase_sphrelax import ALARICCalculator
from ase_sphrelax.drivers.alaric_dynamics import ALARICDynamics
from ase_sphrelax.models import alaric as model

VARIANTS = {
    "paper (baseline: floor 0.05, cfl 0.25, S+F+V)": dict(form="paper"),
    "paper, exact Omega (omega_floor=0)": dict(form="paper", omega_floor=0.0),
    "paper, cfl 0.1": dict(form="paper", cfl=0.1),
    "paper, no viscosity": dict(form="paper", viscosity=False),
    "log (P >= 0: no tensile instability)": dict(form="log"),
}
# a background pressure beta c_s^2 rho (keeps P > 0 near equilibrium): in Eq. 29 (non-conservative) and in the
# conservative least-squares form (energy + beta sum m c_s^2 ln rho), one beta at a time
BACKGROUND = {"squares (least-squares potential, beta = 0)": dict(form="squares")}
for _beta in (0.003, 0.01, 0.03, 0.1):
    BACKGROUND[f"squares, background {_beta}"] = dict(form="squares", background=_beta)
for _beta in (0.01, 0.1):
    BACKGROUND[f"paper, background {_beta}"] = dict(form="paper", background=_beta)
BACKGROUND["log (reference)"] = dict(form="log")
SETS = {"paper": VARIANTS, "background": BACKGROUND}


def line(n):
    pos = np.zeros((n, 3))
    pos[:, 0] = (np.arange(n) + 0.5) * 2.0 / n
    return Atoms(numbers=np.zeros(n, int), positions=pos, cell=[2.0, 0.0, 0.0], pbc=[True, False, False])


def run(n, steps, delta, variant):
    density, gradient = model.eq46(delta)
    calc_opts = {k: variant[k] for k in ("form", "omega_floor", "background") if k in variant}
    dyn_opts = {k: variant[k] for k in ("cfl", "viscosity") if k in variant}
    atoms = line(n)
    atoms.calc = ALARICCalculator(target_density=density, target_gradient=gradient, dim=1, origin=[-1.0], **calc_opts)
    t0 = time.perf_counter()
    error = None
    dyn = ALARICDynamics(atoms, **dyn_opts)
    try:
        dyn.run(steps)
    except Exception as exc:  # noqa: BLE001 - a run that fails is a result of the experiment
        error = f"{type(exc).__name__}: {exc}"
    wall = time.perf_counter() - t0
    res = atoms.calc.results
    eps_trace = [e["epsilon"] for e in dyn.trace]
    half = np.log10(eps_trace[len(eps_trace) // 2:]) if eps_trace else np.array([np.nan])
    x = np.sort(np.mod(atoms.positions[:, 0], 2.0))
    gaps = np.diff(np.concatenate([x, [x[0] + 2.0]]))
    return dict(steps=dyn.nsteps, stop_reason=dyn.stop_reason, error=error, epsilon=float(res["epsilon"]),
                epsilon_lowest=float(min(eps_trace)) if eps_trace else None, checks=len(eps_trace),
                log10_eps_spread_last_half=float(half.max() - half.min()),
                negative_pressure_fraction=float(np.mean(res["density"] < res["target"])),
                min_gap_over_mean=float(gaps.min() / gaps.mean()), min_omega=float(res["omega"].min()),
                wall_s=wall)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=101)
    ap.add_argument("--steps", type=int, default=3000)
    ap.add_argument("--delta", type=float, default=0.1)
    ap.add_argument("--out", default="reproductions/alaric-paper-form/results")
    ap.add_argument("--set", choices=tuple(SETS), default="paper",
                    help="paper: the Eq. 29 ingredients one at a time; background: a background pressure")
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows = {}
    for name, variant in SETS[args.set].items():
        rows[name] = run(args.n, args.steps, args.delta, variant)
        print(name, rows[name], flush=True)
    command = (f"python reproductions/lib/alaric_paper_form_experiments.py --n {args.n} --steps {args.steps} "
               f"--delta {args.delta} --set {args.set} --out {args.out}")
    (out / "results.json").write_text(json.dumps(dict(command=command, n=args.n, steps=args.steps, delta=args.delta,
                                                      runs=rows), indent=1))
    lines = [f"Eq. 46, Delta = {args.delta}, N = {args.n}, at most {args.steps} steps. Command: `{command}`", "",
             "| run | steps | stop | eps final | eps lowest | spread of log10 eps (last half) | rho < rho* fraction (P_eff < 0 in Eq. 29) | "
             "min gap/mean | min Omega | wall s |", "|---|---|---|---|---|---|---|---|---|---|"]
    for name, r in rows.items():
        stop = r["stop_reason"] if r["error"] is None else r["error"].split(":")[0]
        lines.append(f"| {name} | {r['steps']} | {stop} | {r['epsilon']:.2e} | {r['epsilon_lowest']:.2e} | "
                     f"{r['log10_eps_spread_last_half']:.2f} | {r['negative_pressure_fraction']:.2f} | "
                     f"{r['min_gap_over_mean']:.3f} | {r['min_omega']:.3g} | {r['wall_s']:.1f} |")
    (out / "table.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
