"""What sets ALARIC's floor on the declared measure (added after run.py's run; not part of the declared protocol).

From run.py's start (2000 particles uniformly random in the unit circle, seed 0), one ingredient changed at a time,
every state measured by run.py's ``declared_epsilon`` (Eq. 45, mirror ghosts, default eta = 3):

(a) the final epsilon of WVT r^-2 (linear, mirror), ALARIC log form and paper form (eta = 2.5, as run.py) split into
    the interior (particles whose support ``H_a`` of the measure does not reach the circle, ``r < 1 - H_a``; also
    ``r < 1 - 2 H_a``) and the band at the circle, both as shares of the whole epsilon (same denominator) and as
    each region's own Eq. 45 (its own denominator);
(b) the paper form at eta = 3, the measure's eta (background pressure unchanged, "deficit");
(c) the log form's final state continued with the paper form at eta = 3, and the paper form's (eta = 3) final state
    continued with the log form: whether each form leaves the other's fixed point.

Step counts are cut where run.py's traces are already flat (log: 4.59e-6 from step 3000 to 10 000; paper at
eta = 2.5: 8.2e-6 from step 500); WVT keeps its 10 000 steps (its linear schedule spans the run).

    OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 python reproductions/alaric-fig13-declared/floor.py \
        --out reproductions/alaric-fig13-declared/results

It reads run.py's ``results.json`` (its WVT runs, for the goal test in ``summary``); ``--summary-only`` recomputes
``summary`` from an existing ``floor.json`` without running.
"""
from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np
from ase import Atoms

from run import DOMAIN, Recorder, circle_start, goal, run_wvt, uniform_density

from ase_sphrelax import ALARICCalculator
from ase_sphrelax.analysis.alaric import declared_epsilon, nn_min_over_mean
from ase_sphrelax.drivers.alaric_dynamics import ALARICDynamics
from ase_sphrelax.drivers.wvt import WVTRelaxation
from ase_sphrelax.models.alaric import reset_mass


def split_epsilon(x):
    """The declared epsilon of positions ``x`` (N, 2) split into interior and band (see the module docstring)."""
    pos = np.zeros((len(x), 3))
    pos[:, :2] = x[:, :2]
    atoms = Atoms(numbers=np.zeros(len(x), int), positions=pos, pbc=False)
    calc = ALARICCalculator(target_density=uniform_density, dim=2, domain=DOMAIN, boundary="mirror", form="log")
    atoms.calc = calc
    atoms.get_forces()
    r = calc.results
    n, target, h = r["number_density"], r["target"], r["smoothing_lengths"]
    mass = reset_mass(target, n)
    num = (mass * n - target) ** 2 / n
    den = target**2 / n
    total = float(num.sum() / den.sum())
    check = declared_epsilon(x, uniform_density, DOMAIN, 2)["epsilon"]
    if not np.isclose(total, check, rtol=1e-10):
        raise RuntimeError(f"split_epsilon: {total} differs from declared_epsilon {check}")
    radius = np.hypot(x[:, 0], x[:, 1])
    out = dict(epsilon=total, nn_min_over_mean=nn_min_over_mean(x[:, :2]), mean_support=float(h.mean()))
    for label, depth in (("1H", 1.0), ("2H", 2.0)):
        interior = radius < 1.0 - depth * h
        for name, sel in (("interior", interior), ("band", ~interior)):
            dev = mass * n[sel] / target[sel] - 1.0
            out[f"{name}_{label}"] = dict(
                count=int(sel.sum()), share=float(num[sel].sum() / den.sum()),
                own_epsilon=float(num[sel].sum() / den[sel].sum()), mean_deviation=float(dev.mean()),
                rms_deviation=float(np.sqrt(np.mean(dev**2))))
    return out


def run_alaric(steps, form, eta=None, start=None, label=None):
    """ALARIC with mirror ghosts from ``start`` (positions; default run.py's start) for ``steps`` steps."""
    atoms = circle_start(2000, 0)
    if start is not None:
        atoms.positions[:, :2] = start
    calc = ALARICCalculator(target_density=uniform_density, target_gradient=lambda x: np.zeros_like(x), dim=2,
                            domain=DOMAIN, form=form, boundary="mirror", eta=eta)
    atoms.calc = calc
    dyn = ALARICDynamics(atoms, eps_dot_min=0.0, eps_min=0.0)
    rec = Recorder(dyn, atoms, steps)
    dyn.attach(rec, interval=1)
    rec.start()
    dyn.run(steps)
    rec(force=True)
    x = atoms.positions[:, :2].copy()
    return dict(label=label, kind="alaric", form=form, eta=calc.eta, steps=int(dyn.nsteps),
                cpu_s=rec.rows[-1][2], wall_s=rec.rows[-1][1], trace=rec.measured(), final=split_epsilon(x)), x


def run_wvt_linear(steps):
    """run.py's WVT r^-2 (linear schedule, mirror ghosts) from its start; run.py's ``run_wvt`` keeps no positions."""
    atoms = circle_start(2000, 0)
    opt = WVTRelaxation(atoms, uniform_density, 2, steps=steps, weight="r2", domain=DOMAIN, schedule="linear",
                        boundary="mirror")
    rec = Recorder(opt, atoms, steps)
    opt.attach(rec, interval=1)
    rec.start()
    opt.run()
    rec(force=True)
    return dict(label="wvt_linear", kind="wvt", steps=int(opt.nsteps), cpu_s=rec.rows[-1][2], wall_s=rec.rows[-1][1],
                trace=rec.measured(), final=split_epsilon(atoms.positions[:, :2].copy()))


def summarise(data, main_run):
    """Per run: the band's share of the final epsilon, the first checkpoint at a tenth of WVT's final epsilon,
    and run.py's goal test (``run.goal``, CPU clock) against this file's WVT and run.py's two WVT runs with ghosts
    (the last two for the ALARIC runs from run.py's start)."""
    wvts = [dict(method="WVT r^-2 (linear, mirror), floor.py", epsilon=r["final"]["epsilon"], cpu_s=r["cpu_s"])
            for r in data["runs"] if r["kind"] == "wvt"]
    wvts += [r for r in main_run["runs"] if r["kind"] == "wvt" and r["boundary"] == "mirror"]
    out = {}
    for r in data["runs"]:
        f = r["final"]
        row = dict(epsilon=f["epsilon"], band_fraction_1H=f["band_1H"]["share"] / f["epsilon"],
                   band_fraction_2H=f["band_2H"]["share"] / f["epsilon"],
                   band_over_interior_1H=f["band_1H"]["own_epsilon"] / f["interior_1H"]["own_epsilon"],
                   no_pairing=bool(f["nn_min_over_mean"] >= 0.5))
        if r["kind"] == "alaric" and "_from_" not in r["label"]:  # from run.py's start only
            tenth = wvts[0]["epsilon"] / 10.0
            hit = [t for t in r["trace"] if t["epsilon"] <= tenth]
            row["first_step_below_tenth_wvt"] = hit[0]["step"] if hit else None
            row["cpu_s_at_first_step_below_tenth_wvt"] = hit[0]["cpu_s"] if hit else None
            a = dict(method=r["label"], trace=r["trace"], epsilon=f["epsilon"], cpu_s=r["cpu_s"])
            row["goals"] = [goal(a, w, "cpu_s") for w in wvts]
        out[r["label"]] = row
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--summary-only", action="store_true", help="recompute the summary of an existing floor.json")
    ap.add_argument("--log-steps", type=int, default=3000)
    ap.add_argument("--paper-steps", type=int, default=1500)
    ap.add_argument("--paper3-steps", type=int, default=3000)
    ap.add_argument("--cont-steps", type=int, default=1000)
    ap.add_argument("--wvt-steps", type=int, default=10000)
    ap.add_argument("--out", default="reproductions/alaric-fig13-declared/results")
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    command = ("python reproductions/alaric-fig13-declared/floor.py " + " ".join(
        f"--{k.replace('_', '-')} {v}" for k, v in vars(args).items() if k != "summary_only"))
    threads = {k: os.environ.get(k) for k in ("OMP_NUM_THREADS", "NUMBA_NUM_THREADS")}
    main_run = json.loads((out / "results.json").read_text())
    if args.summary_only:
        data = json.loads((out / "floor.json").read_text())
        data["summary"] = summarise(data, main_run)
        (out / "floor.json").write_text(json.dumps(data, indent=1) + "\n")
        return
    run_wvt(200, 3, 0, "linear", "mirror")  # numba compiles on first use
    for form in ("log", "paper"):
        calc = ALARICCalculator(target_density=uniform_density, dim=2, domain=DOMAIN, form=form, boundary="mirror")
        a = circle_start(200, 0)
        a.calc = calc
        ALARICDynamics(a, eps_dot_min=0.0, eps_min=0.0).run(3)
    c0 = time.process_time()
    data = dict(command=command, threads=threads, start=split_epsilon(circle_start(2000, 0).positions[:, :2]), runs=[])

    def save(row):
        data["runs"].append(row)
        data["cpu_s_total"] = time.process_time() - c0
        (out / "floor.json").write_text(json.dumps(data, indent=1) + "\n")
        print({k: v for k, v in row.items() if k != "trace"}, flush=True)

    save(run_wvt_linear(args.wvt_steps))
    row, x_log = run_alaric(args.log_steps, "log", label="log")
    save(row)
    row, _ = run_alaric(args.paper_steps, "paper", label="paper_eta2.5")
    save(row)
    row, x_p3 = run_alaric(args.paper3_steps, "paper", eta=3.0, label="paper_eta3")
    save(row)
    row, _ = run_alaric(args.cont_steps, "paper", eta=3.0, start=x_log, label="paper_eta3_from_log")
    save(row)
    row, _ = run_alaric(args.cont_steps, "log", start=x_p3, label="log_from_paper_eta3")
    save(row)
    data["summary"] = summarise(data, main_run)
    (out / "floor.json").write_text(json.dumps(data, indent=1) + "\n")


if __name__ == "__main__":
    main()
