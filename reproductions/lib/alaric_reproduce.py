"""Reproduce the ALARIC paper's tables and figures (Vela Vela et al.), plus one comparison beyond it.

    python reproductions/lib/alaric_reproduce.py --only a,b,... [--quick] --out reproductions/<id>/results

One registry entry per part (``--out`` its ``results/``), e.g. ``--only a --out
reproductions/alaric-table1/results``; writes under ``--out``: ``table1.md`` (a), ``table2.md`` (b), ``fig6.png`` (c), ``fig8.png`` (d),
``fig10_11.png`` (e), ``fig13.png`` (f), ``fig_optimizers.png`` (g), every number in ``results.json``
(merged with what earlier runs wrote), and ``load.txt`` (load average before and after each part).

(a) Table 1: 1D Eq. 46, 300 particles, Delta = 0, the eight combinations of S, F, V, for the log
    potential (default) and the paper's Eq. 29 form; steps to converge (eps, eps_dot < 1e-8, cap
    10000), CPU time, residual eps.
(a2) Table 1 with the log potential followed by the least-squares potential (``--finish squares``), with the
    smallest gap (pairing): ``table1_forms/``.
(b) Table 2: eps_stag for Delta in {0, 0.01, 0.05, 0.1, 0.5, 1}, 101 particles split once to 303,
    against eps_teo.min of Eq. 48; the dynamics (log potential) and after the least-squares polish.
(b2) Table 2's limiting ingredient, isolated (``reproductions/alaric-table2/results/isolate.md``): for one Delta (``--deltas``, default
    0.1) the issue's command (the log potential's dynamics, stopped by eps_dot), then from its final state the
    same driver with only the potential changed (log / least squares / Eq. 29, 4000 more steps, no stop), and LBFGS
    on the log and on the least-squares potential (4000 steps, the same scales): eps of Eq. 45, its integral
    form on a grid, the smallest gap and the particle closest to the bottom of the well.
(c) Fig. 6: 909 particles, 0, 1 and 2 splitting stages, eps traces.
(d) Fig. 8: radial profiles in 1D, 2D and 3D with N = 77 * 7^d (3D: 77 * 5^3; 2D/3D: unit disc/ball,
    step caps 10000 and 1500).
(e) Figs. 10-11: Eq. 49 in the unit disc, 10 000 particles, p = 1, 2, 3 (step cap 4000).
(f) Sec. 5.1 / Fig. 13: 2000 particles, uniform density in a circle from one random start: ALARIC
    against WVT (r^-2 and kernel weights): eps against steps and wall time.
(g) FIRE and LBFGS on the ALARIC potential (and LBFGS on the least-squares potential) against
    ALARIC's dynamics on (a) and (f): eps against force evaluations.
(h) Beyond the paper: nearest-neighbour statistics of the circle after the dynamics, the least-squares
    polish and WVT (a low eps is not a regular arrangement in 2D).
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # reproductions/, for ``from lib import x``

import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from ase import Atoms  # noqa: E402

from ase_sphrelax import ALARICCalculator  # noqa: E402
from ase_sphrelax.analysis.alaric import alaric_min_error  # noqa: E402
from ase_sphrelax.domains import Circle  # noqa: E402
from ase_sphrelax.drivers.alaric_dynamics import (ALARICDynamics, polish_least_squares, relax_density,  # noqa: E402
                                                 start_atoms)
from ase_sphrelax.drivers.wvt import WVTRelaxation  # noqa: E402
from ase_sphrelax.models import alaric as model  # noqa: E402

PAPER_TABLE1 = {  # run: (time steps, CPU time [s], residual eps)
    "Reference": ("> 10000", "> 100", 0.1700), "V": ("> 10000", "> 100", 0.0034), "S": ("> 10000", "> 100", 0.0013),
    "S+V": ("> 10000", "> 100", 0.0002), "F": (6841, 64, 0.0002), "F+V": (6486, 78, 0.0002),
    "S+F+V": (4218, 49, 0.0002), "S+F": (4219, 36, 0.0002)}
PAPER_TABLE2 = {0.0: ("1e-4", "2e-4"), 0.01: ("7e-5", "1e-4"), 0.05: ("9e-6", "2e-5"), 0.1: ("8e-7", "2e-6"),
                0.5: ("1e-9", "< 1e-8"), 1.0: ("8e-11", "< 1e-8")}
COMBOS = {"Reference": (False, False, False), "V": (False, False, True), "S": (True, False, False),
          "S+V": (True, False, True), "F": (False, True, False), "F+V": (False, True, True),
          "S+F+V": (True, True, True), "S+F": (True, True, False)}


def line_atoms(n, delta, form="log"):
    atoms, origin, _ = start_atoms(n, 1)
    density, gradient = model.eq46(delta)
    atoms.calc = ALARICCalculator(target_density=density, target_gradient=gradient, dim=1, origin=origin, form=form)
    return atoms


def eps_of(atoms, calc):
    """eps of Eq. 45 with the Eq. 44 mass (for any driver and form: the paper's Eq. 29 form has no energy)."""
    atoms.get_forces()
    r = calc.results
    m = model.reset_mass(r["target"], r["number_density"])
    return model.epsilon(m * r["number_density"], r["target"], r["number_density"])


# -- (a) ------------------------------------------------------------------------------------------
def table1(quick):
    cap = 2000 if quick else 10000
    rows = {}
    for form in ("log", "paper"):
        for name, (s, f, v) in COMBOS.items():
            atoms = line_atoms(300, 0.0, form)
            dyn = ALARICDynamics(atoms, velocity_stop=s, friction=2.0 if f else 0.0, viscosity=v)
            t0 = time.process_time()
            try:
                dyn.run(cap)
                stop = dyn.stop_reason
            except (FloatingPointError, ValueError) as exc:  # an unstable run is a result, reported as such
                stop = f"failed at step {dyn.nsteps}: {type(exc).__name__}"
                print(f"(a) {form} {name}: {exc}", flush=True)
            cpu = time.process_time() - t0
            rows[f"{form}:{name}"] = dict(form=form, run=name, steps=dyn.nsteps, cpu_s=cpu, stop=stop,
                                          epsilon=dyn.trace[-1]["epsilon"] if dyn.trace else None,
                                          trace=[(e["step"], e["epsilon"]) for e in dyn.trace])
            print(f"(a) {form:5s} {name:9s} steps {dyn.nsteps:6d} cpu {cpu:6.1f} s eps {rows[f'{form}:{name}']['epsilon']:.2e} "
                  f"({stop})", flush=True)
    lines = ["# Table 1: 1D Eq. 46, 300 particles, Delta = 0", "",
             f"Convergence: eps or eps_dot below 1e-8 (checked at each velocity stop / interval end), cap {cap} steps. "
             f"Command: `python reproductions/lib/alaric_reproduce.py --only a{' --quick' if quick else ''}` "
             f"({time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, load average {os.getloadavg()[0]:.1f} at the end; "
             "CPU: process time of each run, on a shared 2-vCPU machine); every number in `results.json` (`table1`).",
             "", "| run | paper steps | paper CPU [s] | paper eps | log: steps | log: CPU [s] | log: eps | log: stop "
             "| Eq. 29: steps | Eq. 29: CPU [s] | Eq. 29: eps | Eq. 29: stop |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for name in COMBOS:
        p = PAPER_TABLE1[name]
        cells = [name, str(p[0]), str(p[1]), f"{p[2]:.4f}"]
        for form in ("log", "paper"):
            r = rows[f"{form}:{name}"]
            cells += [str(r["steps"]), f"{r['cpu_s']:.1f}", f"{r['epsilon']:.2e}", r["stop"]]
        lines.append("| " + " | ".join(cells) + " |")
    return rows, "\n".join(lines) + "\n"


def _min_gap_over_mean(atoms):
    x = np.sort(np.mod(atoms.positions[:, 0], 2.0))
    gaps = np.diff(np.concatenate([x, [x[0] + 2.0]]))
    return float(gaps.min() / gaps.mean())


def _table1_run(form, combo, cap):
    """One Table 1 run: ``form`` "log", "paper" (Eq. 29) or "log+squares" (the log potential until its
    epsilon_dot stop, then the least-squares potential with the same ingredients, within the same cap)."""
    s, f, v = combo
    options = dict(velocity_stop=s, friction=2.0 if f else 0.0, viscosity=v)
    atoms = line_atoms(300, 0.0, "paper" if form == "paper" else "log")
    dyn = ALARICDynamics(atoms, **options)
    t0 = time.process_time()
    stop, steps, trace = None, 0, []
    try:
        dyn.run(cap)
        stop, steps = dyn.stop_reason, dyn.nsteps
        trace = [(e["step"], e["epsilon"]) for e in dyn.trace]
        if form == "log+squares" and stop == "epsilon_dot" and steps < cap:
            atoms.calc.set(form="squares")
            second = ALARICDynamics(atoms, **options)
            second.run(cap - steps)
            stop = f"log: epsilon_dot at {steps}, squares: {second.stop_reason}"
            trace += [(steps + e["step"], e["epsilon"]) for e in second.trace]
            steps += second.nsteps
    except (FloatingPointError, ValueError) as exc:  # an unstable run is a result, reported as such
        stop = f"failed at step {dyn.nsteps}: {type(exc).__name__}"
    cpu = time.process_time() - t0
    return dict(form=form, steps=steps, cpu_s=cpu, stop=stop, epsilon=trace[-1][1] if trace else None,
                min_gap_over_mean=_min_gap_over_mean(atoms), trace=trace)


def table1_forms(quick, forms=("log+squares",)):
    """(a2) Table 1 with the log potential followed by the least-squares potential: steps, CPU, eps, pairing (the
    log and Eq. 29 columns: part (a), ``table1.md``)."""
    cap = 2000 if quick else 10000
    rows = {}
    for form in forms:
        for name, combo in COMBOS.items():
            rows[f"{form}:{name}"] = r = _table1_run(form, combo, cap)
            print(f"(a2) {form:11s} {name:9s} steps {r['steps']:6d} cpu {r['cpu_s']:6.1f} s eps {r['epsilon']:.2e} "
                  f"gap {r['min_gap_over_mean']:.3f} ({r['stop']})", flush=True)
    head = " | ".join(f"{f}: steps | {f}: CPU [s] | {f}: eps | {f}: min gap/mean | {f}: stop" for f in forms)
    lines = ["# Table 1: 1D Eq. 46, 300 particles, Delta = 0", "",
             f"Convergence: eps or eps_dot below 1e-8 (checked at each velocity stop / interval end), cap {cap} steps "
             "in all (log+squares: both stages together). CPU: process time, on a shared 2-core machine.", "",
             f"| run | paper steps | paper CPU [s] | paper eps | {head} |",
             "|---|---|---|---|" + "---|" * (5 * len(forms))]
    for name in COMBOS:
        p = PAPER_TABLE1[name]
        cells = [name, str(p[0]), str(p[1]), f"{p[2]:.4f}"]
        for form in forms:
            r = rows[f"{form}:{name}"]
            cells += [str(r["steps"]), f"{r['cpu_s']:.1f}", f"{r['epsilon']:.2e}", f"{r['min_gap_over_mean']:.3f}",
                      str(r["stop"])]
        lines.append("| " + " | ".join(cells) + " |")
    return rows, "\n".join(lines) + "\n"


# -- (b) ------------------------------------------------------------------------------------------
def table2(quick):
    rows = {}
    for delta in PAPER_TABLE2:
        atoms, origin, _ = start_atoms(101, 1)
        density, gradient = model.eq46(delta)
        out = relax_density(atoms, density, 1, target_gradient=gradient, splits=1, origin=origin,
                            max_steps=6000 if quick else 30000, polish_steps=1000 if quick else 4000, form="log")
        teo = alaric_min_error(303, delta, 1)
        rows[str(delta)] = dict(delta=delta, teo=teo, eps_dynamics=out["epsilon_dynamics"], eps=out["epsilon"],
                                steps=out["steps"], stop=out["stop_reason"], wall_s=out["wall_time"],
                                trace=[(e["step"], e["epsilon"]) for e in out["trace"]])
        print(f"(b) Delta {delta:5.2f}: eps_teo {teo:.2e} dynamics {out['epsilon_dynamics']:.2e} "
              f"polished {out['epsilon']:.2e} ({out['steps']} steps, {out['wall_time']:.0f} s)", flush=True)
    lines = ["# Table 2: eps_stag against eps_teo.min (Eq. 48), 101 particles split once to 303", "",
             "| Delta | paper eps_teo.min | ours eps_teo.min (Eq. 48) | paper eps_stag | ours: dynamics (log potential) "
             "| ours: + least-squares polish | never below Eq. 48 |", "|---|---|---|---|---|---|---|"]
    for delta, (pt, ps) in PAPER_TABLE2.items():
        r = rows[str(delta)]
        ok = "yes" if min(r["eps"], r["eps_dynamics"]) >= r["teo"] else "**no**"
        lines.append(f"| {delta:g} | {pt} | {r['teo']:.2e} | {ps} | {r['eps_dynamics']:.2e} | {r['eps']:.2e} | {ok} |")
    return rows, "\n".join(lines) + "\n"


# -- (b2) -----------------------------------------------------------------------------------------
ISOLATE_STEPS = 4000


def _line_state(atoms):
    """Eq. 46 line diagnostics of ``atoms`` (cell [0, 2), origin -1) with its calculator's current results."""
    calc = atoms.calc
    atoms.get_forces()
    r = calc.results
    m = model.reset_mass(r["target"], r["number_density"])
    rho_p = m * r["number_density"]
    x_p = np.mod(atoms.positions[:, 0], 2.0) - 1.0  # physical coordinates in [-1, 1) (origin -1)
    return dict(epsilon=float(model.epsilon(rho_p, r["target"], r["number_density"])), mass=float(m),
                max_rel_error=float(np.max(np.abs(rho_p / r["target"] - 1.0))),
                min_gap_over_mean=_min_gap_over_mean(atoms), r_min=float(np.abs(x_p).min()),
                x_p=x_p, h_p=np.array(r["smoothing_lengths"]))


def _integral_epsilon(x_p, h_p, mass, delta):
    from lib.alaric_table2_summary import integral_epsilon  # the same grid measure as table2_*/integral.md

    line = Atoms(numbers=np.zeros(len(x_p), int), positions=np.column_stack([x_p, np.zeros((len(x_p), 2))]))
    line.new_array("h", h_p)
    line.set_masses(np.full(len(x_p), mass))
    return integral_epsilon(line, delta)


def _lbfgs(atoms, steps, mass, cs2=1.0):
    """LBFGS on the attached calculator's potential with polish_least_squares' scales (alpha, maxstep, memory);
    eps of Eq. 45 every 250 steps. Ends at the last positions."""
    from ase.optimize import LBFGS

    calc = atoms.calc
    calc.silence_scale_hint()  # the steps below are scaled to the potential (alpha, maxstep)
    atoms.get_forces()
    spacing = float(np.mean(calc.results["smoothing_lengths"])) / calc.eta
    rho_ref = float(np.mean(calc.results["target"]))
    opt = LBFGS(atoms, logfile=None, maxstep=0.15 * spacing, alpha=10.0 * mass * cs2 * rho_ref / spacing**2,
                memory=20)
    trace = []
    for done in range(250, steps + 1, 250):
        kept = atoms.positions.copy()
        try:
            opt.run(fmax=1e-14, steps=250)
        except ValueError:  # ASE's LBFGS goes NaN once y.s = 0 (nothing left to gain): end at the last chunk
            atoms.positions = kept
            trace.append((done - 250, eps_of(atoms, calc), "LBFGS stalled (y.s = 0), last finite chunk kept"))
            break
        trace.append((done, eps_of(atoms, calc)))
    return trace


def table2_isolate(quick, out, deltas=(0.1,)):
    """(b2) One ingredient at a time from the log potential's converged Table 2 state."""
    import subprocess
    import sys

    from ase.io import read

    steps = 500 if quick else ISOLATE_STEPS
    folder = out / "isolate"
    folder.mkdir(parents=True, exist_ok=True)
    rows = []
    for delta in deltas:
        start_dir = folder / f"delta_{delta:g}"
        command = [sys.executable, "-m", "ase_sphrelax.cli", "density", "--profile", "eq46", "--delta", f"{delta:g}",
                   "--dim", "1", "--n", "303", "--split", "1", "--no-polish", "--form", "log", "--overwrite", "--out",
                   str(start_dir)]
        subprocess.run(command, check=True, capture_output=True, text=True)
        summary = json.loads((start_dir / "summary.json").read_text())
        relaxed = read(start_dir / "relaxed.extxyz")
        origin = np.array(relaxed.info["origin"], dtype=float)
        density, gradient = model.eq46(delta)

        def fresh(form, mass=None):
            atoms = Atoms(numbers=np.zeros(len(relaxed), int), cell=[2.0, 0.0, 0.0], pbc=[True, False, False],
                          positions=relaxed.positions - np.array([origin[0], 0.0, 0.0]))
            atoms.wrap()
            atoms.calc = ALARICCalculator(target_density=density, target_gradient=gradient, dim=1, origin=origin,
                                          form=form, mass=mass)
            return atoms

        def record(label, potential, driver, atoms, cpu, extra=None):
            state = _line_state(atoms)
            row = dict(delta=delta, run=label, potential=potential, driver=driver, cpu_s=cpu,
                       epsilon=state["epsilon"], max_rel_error=state["max_rel_error"],
                       min_gap_over_mean=state["min_gap_over_mean"], r_min=state["r_min"],
                       epsilon_integral=_integral_epsilon(state["x_p"], state["h_p"], state["mass"], delta),
                       epsilon_teo_min=summary["epsilon_teo_min"], **(extra or {}))
            rows.append(row)
            print(f"(b2) Delta {delta:g} {label}: eps {row['epsilon']:.3e}, integral {row['epsilon_integral']:.3e}, "
                  f"gap {row['min_gap_over_mean']:.3f}, r_min {row['r_min']:.3g} ({cpu:.1f} s)", flush=True)

        record("A: the issue's command", "log", f"ALARIC S+F+V, {summary['steps']} steps, {summary['stop_reason']}",
               fresh("log", summary["mass"]), summary["wall_time_s"],
               dict(command=" ".join(["sphrelax"] + command[3:]), steps=summary["steps"]))
        for form in ("log", "squares", "paper"):
            atoms = fresh(form)
            dyn = ALARICDynamics(atoms, eps_min=0.0, eps_dot_min=0.0)
            c0 = time.process_time()
            dyn.run(steps)
            record(f"A + {steps} steps of the dynamics, form {form}", form,
                   f"ALARIC S+F+V, {steps} more steps (no stop)", atoms, time.process_time() - c0,
                   dict(trace=[(e["step"], e["epsilon"]) for e in dyn.trace]))
        for form in ("log", "squares"):
            atoms = fresh(form, summary["mass"])
            c0 = time.process_time()
            trace = _lbfgs(atoms, steps, summary["mass"])
            record(f"A + LBFGS, form {form}", form, f"LBFGS, {trace[-1][0]} steps"
                   + (" (then stalled: y.s = 0)" if len(trace[-1]) > 2 else ""), atoms,
                   time.process_time() - c0, dict(trace=trace, lowest_epsilon=min(t[1] for t in trace),
                        lbfgs_steps=trace[-1][0]))
    command = f"python reproductions/lib/alaric_reproduce.py --only b2{' --quick' if quick else ''} --out {out}"
    lines = ["# Table 2's limiting ingredient, isolated (issue 20 item 2)", "",
             f"Command: `{command}` ({time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, load average "
             f"{os.getloadavg()[0]:.1f}); every number in `isolate.json`. Eq. 46, 101 particles split once to 303. "
             "Row A is the issue's Table 2 command (`sphrelax density --profile eq46 --delta D --dim 1 --n 303 "
             "--split 1 --no-polish`, the log potential, stopped by its eps_dot criterion; its files in "
             "`isolate/delta_D/`). Every other row starts from A's final positions and changes one thing: the "
             "potential (log, least squares, the paper's Eq. 29) under the same ALARIC dynamics (S+F+V, Eq. 44 mass "
             "reset, no stop), or the potential under the same LBFGS (polish_least_squares' scales). eps: Eq. 45 with "
             "the Eq. 44 mass; integral eps: the grid form of `alaric_table2_summary.py` (sees an empty well); gap: the "
             "smallest particle gap over the mean (pairing below 0.5); r_min: the particle closest to the bottom of "
             "the well.", "",
             "| Delta | run | potential | driver | eps (Eq. 45) | Eq. 48 | integral eps | max abs(rho/rho* - 1) "
             "| min gap / mean | r_min | CPU s (A: wall) |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['delta']:g} | {r['run']} | {r['potential']} | {r['driver']} | {r['epsilon']:.2e} | "
                     f"{r['epsilon_teo_min']:.2e} | {r['epsilon_integral']:.2e} | {r['max_rel_error']:.3g} | "
                     f"{r['min_gap_over_mean']:.3f} | {r['r_min']:.3g} | {r['cpu_s']:.1f} |")
    (folder.parent / "isolate.md").write_text("\n".join(lines) + "\n")
    (folder.parent / "isolate.json").write_text(json.dumps(dict(command=command, load_average=os.getloadavg(),
                                                                rows=rows), indent=1, default=float))
    return rows


# -- (c) ------------------------------------------------------------------------------------------
def fig6(quick, out):
    rows = {}
    fig, ax = plt.subplots(figsize=(6, 4))
    for splits in (0, 1, 2):
        atoms = line_atoms(909 // 3**splits, 0.0)
        dyn = ALARICDynamics(atoms, splits=splits, eps_dot_min=1e-8)
        t0 = time.perf_counter()
        dyn.run(4000 if quick else 10000)
        rows[str(splits)] = dict(steps=dyn.nsteps, eps=dyn.trace[-1]["epsilon"], wall_s=time.perf_counter() - t0,
                                 stop=dyn.stop_reason,
                                 trace=[(e["time"], e["epsilon"], e["n"]) for e in dyn.trace])
        t = [e["time"] for e in dyn.trace]
        ax.loglog(t, [e["epsilon"] for e in dyn.trace], label=f"{splits} splitting stage(s)")
        print(f"(c) {splits} splits: {dyn.nsteps} steps, eps {dyn.trace[-1]['epsilon']:.2e} ({dyn.stop_reason})",
              flush=True)
    ax.axhline(alaric_min_error(909, 0.0, 1), color="k", ls=":", label="Eq. 48, N = 909")
    ax.set_xlabel("time")
    ax.set_ylabel("epsilon (Eq. 45)")
    ax.set_title("Fig. 6: 909 particles, Delta = 0 (log potential, S+F+V)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "fig6.png", dpi=120)
    plt.close(fig)
    return rows


# -- (d) ------------------------------------------------------------------------------------------
def fig8(quick, out):
    rows = {}
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.8))
    delta = 0.01
    for dim, ax in zip((1, 2, 3), axes):
        # the paper's N = 77 * 7^d, except 3D: 77 * 5^3 (26411 particles take about 2.5 s per step here)
        n = (77 * 7**dim if dim < 3 else 77 * 5**3) if not quick else 77 * 3**dim
        p = {1: 3, 2: 4, 3: 5}[dim]
        n0 = n // p
        n = n0 * p
        atoms, origin, domain = start_atoms(n0, dim)
        density, gradient = model.eq46(delta)
        cap = {1: 20000, 2: 10000, 3: 1500}[dim] if not quick else 300
        res = relax_density(atoms, density, dim, target_gradient=gradient, splits=1, domain=domain, origin=origin,
                            polish=dim == 1, max_steps=cap, form="log")
        calc = res["calculator"]
        r = calc.results
        x = calc.points(res["atoms"].positions, res["atoms"])
        radius = np.linalg.norm(x, axis=1)
        order = np.argsort(radius)
        ax.plot(radius[order], r["target"][order], "k-", lw=1, label="rho*")
        ax.plot(radius, r["density"], ".", ms=2, label="rho_a")
        ax.set_xlim(0, 1)
        ax.set_xlabel("r")
        ax.set_title(f"{dim}D, N = {n}, eps = {res['epsilon']:.1e}")
        inner = int(np.sum(radius < 0.15))
        rows[str(dim)] = dict(n=n, eps=res["epsilon"], steps=res["steps"], stop=res["stop_reason"],
                              wall_s=res["wall_time"], particles_within_0_15=inner,
                              closest_to_centre=float(radius.min()), teo=alaric_min_error(n, delta, dim))
        print(f"(d) {dim}D N {n}: eps {res['epsilon']:.2e} ({res['steps']} steps, {res['wall_time']:.0f} s), "
              f"closest particle at r = {radius.min():.3g}", flush=True)
    axes[0].legend()
    fig.suptitle(f"Fig. 8: radial profiles, Eq. 46 with Delta = {delta}")
    fig.tight_layout()
    fig.savefig(out / "fig8.png", dpi=120)
    plt.close(fig)
    return rows


# -- (e) ------------------------------------------------------------------------------------------
def fig10_11(quick, out):
    rows = {}
    n = 2500 if quick else 10000
    fig, axes = plt.subplots(2, 3, figsize=(13, 8.5))
    for k, p in enumerate((1, 2, 3)):
        atoms, origin, domain = start_atoms(n // 4, 2)
        density, gradient = model.eq49(p)
        res = relax_density(atoms, density, 2, target_gradient=gradient, splits=1, domain=domain,
                            max_steps=600 if quick else 4000, form="log")
        r = res["calculator"].results
        x = res["atoms"].positions
        axes[0, k].scatter(x[:, 0], x[:, 1], s=0.3, c="k")
        sc = axes[1, k].scatter(x[:, 0], x[:, 1], s=1.5, c=r["density"], cmap="RdBu_r")
        for ax in axes[:, k]:
            ax.set_aspect("equal")
            ax.set_xticks([])
            ax.set_yticks([])
        axes[0, k].set_title(f"p = {p}: particles (N = {len(x)})")
        axes[1, k].set_title(f"SPH density, eps = {res['epsilon']:.1e}")
        fig.colorbar(sc, ax=axes[1, k], shrink=0.7)
        rows[str(p)] = dict(n=len(x), eps=res["epsilon"], eps_dynamics=res["epsilon_dynamics"], steps=res["steps"],
                            stop=res["stop_reason"], wall_s=res["wall_time"])
        print(f"(e) p = {p}: N {len(x)} eps {res['epsilon']:.2e} (dynamics {res['epsilon_dynamics']:.2e}, "
              f"{res['steps']} steps, {res['wall_time']:.0f} s)", flush=True)
    fig.suptitle("Figs. 10-11: Eq. 49 in the unit disc")
    fig.tight_layout()
    fig.savefig(out / "fig10_11.png", dpi=110)
    plt.close(fig)
    return rows


# -- (f) and (g) ------------------------------------------------------------------------------------
def circle_start(n, seed=0):
    rng = np.random.default_rng(seed)
    r = np.sqrt(rng.uniform(0, 1, n))
    t = rng.uniform(0, 2 * np.pi, n)
    pos = np.zeros((n, 3))
    pos[:, 0], pos[:, 1] = r * np.cos(t), r * np.sin(t)
    return Atoms(numbers=np.zeros(n, int), positions=pos, pbc=False)


def uniform_density(x):
    return np.ones(len(x))


def fig13(quick, out):
    n = 2000
    steps = 1000 if quick else 10000
    domain = Circle((0.0, 0.0), 1.0)
    rows = {}
    # ALARIC
    atoms = circle_start(n)
    calc = ALARICCalculator(target_density=uniform_density, dim=2, domain=domain, form="log")
    atoms.calc = calc
    eps0 = eps_of(atoms, calc)
    dyn = ALARICDynamics(atoms, eps_dot_min=0.0, eps_min=0.0)
    t0 = time.perf_counter()
    trace = [(0, eps0, 0.0, 1)]

    def record():
        trace.append((dyn.nsteps, calc.results["epsilon"], time.perf_counter() - t0, dyn.force_calls))

    marks = set(np.unique(np.logspace(0, np.log10(steps), 40).astype(int)).tolist())
    dyn.attach(lambda: record() if dyn.nsteps in marks else None, interval=1)
    dyn.run(steps)
    rows["ALARIC"] = dict(trace=trace, eps=trace[-1][1], wall_s=time.perf_counter() - t0, steps=dyn.nsteps)
    print(f"(f) ALARIC: eps {trace[-1][1]:.2e} after {dyn.nsteps} steps, {rows['ALARIC']['wall_s']:.0f} s", flush=True)
    # ALARIC's dynamics (log potential) followed by LBFGS on the least-squares potential
    wall = time.perf_counter() - t0
    mass = model.reset_mass(calc.results["target"], calc.results["number_density"])
    t1 = time.perf_counter()
    eps_p, ptrace, _ = polish_least_squares(atoms, uniform_density, 2, mass, lambda x: np.zeros_like(x),
                                            domain=domain, steps=300 if quick else 3000, chunk=100)
    rows["ALARIC + polish"] = dict(trace=[(dyn.nsteps + e["step"], e["epsilon"],
                                           wall + (time.perf_counter() - t1) * e["step"] / ptrace[-1]["step"],
                                           dyn.force_calls + e["step"]) for e in ptrace],
                                   eps=eps_p, wall_s=wall + time.perf_counter() - t1, steps=dyn.nsteps)
    print(f"(f) ALARIC + polish: eps {eps_p:.2e}", flush=True)
    # WVT
    for weight in ("r2", "kernel"):
        atoms = circle_start(n)
        probe = ALARICCalculator(target_density=uniform_density, dim=2, domain=domain, form="log")
        atoms.calc = probe
        opt = WVTRelaxation(atoms, uniform_density, 2, steps=steps, weight=weight, domain=domain)
        t0 = time.perf_counter()
        probe_time = 0.0
        wtrace = [(0, eps0, 0.0, 0)]
        for _ in opt.irun():
            if opt.nsteps in marks:
                t1 = time.perf_counter()
                e = eps_of(atoms, probe)
                probe_time += time.perf_counter() - t1
                wtrace.append((opt.nsteps, e, time.perf_counter() - t0 - probe_time, opt.nsteps))
        rows[f"WVT-{weight}"] = dict(trace=wtrace, eps=wtrace[-1][1], wall_s=wtrace[-1][2], steps=opt.nsteps)
        print(f"(f) WVT {weight}: eps {wtrace[-1][1]:.2e} after {opt.nsteps} steps, {wtrace[-1][2]:.0f} s", flush=True)
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for name, r in rows.items():
        tr = np.array(r["trace"])
        axes[0].loglog(np.maximum(tr[:, 0], 1), tr[:, 1], label=name)
        axes[1].loglog(np.maximum(tr[:, 2], 1e-3), tr[:, 1], label=name)
    axes[0].set_xlabel("time steps")
    axes[1].set_xlabel("wall time [s] (eps probes excluded)")
    for ax in axes:
        ax.set_ylabel("epsilon (Eq. 45)")
        ax.legend()
    fig.suptitle("Fig. 13: 2000 particles, uniform density in a circle, one random start")
    fig.tight_layout()
    fig.savefig(out / "fig13.png", dpi=120)
    plt.close(fig)
    return rows


def optimizers(quick, out, circle_rows):
    from ase.optimize import FIRE, LBFGS

    rows = {}
    budget = 1500 if quick else 3000
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    cases = {"(a) 1D Eq. 46, N = 300, Delta = 0": "line", "(f) circle, N = 2000": "circle"}
    for ax, (title, case) in zip(axes, cases.items()):
        for name in ("ALARIC dynamics", "FIRE (log)", "LBFGS (log)", "LBFGS (squares)"):
            if case == "line":
                atoms = line_atoms(300, 0.0, "squares" if "squares" in name else "log")
                calc = atoms.calc
                spacing = 2.0 / 300
            else:
                atoms = circle_start(2000)
                calc = ALARICCalculator(target_density=uniform_density, dim=2, domain=Circle((0, 0), 1.0),
                                        form="squares" if "squares" in name else "log")
                atoms.calc = calc
                spacing = np.sqrt(np.pi / 2000)
            trace = [(0, eps_of(atoms, calc))]
            t0 = time.perf_counter()
            if name == "ALARIC dynamics":
                dyn = ALARICDynamics(atoms, eps_dot_min=0.0, eps_min=0.0)
                dyn.attach(lambda: trace.append((dyn.force_calls, calc.results["epsilon"])) if dyn.nsteps % 20 == 0
                           else None, interval=1)
                dyn.run(budget)
            else:
                f0 = float(np.abs(atoms.get_forces()).max())
                if name.startswith("FIRE"):
                    dt = np.sqrt(0.01 * spacing / max(f0, 1e-30))
                    opt = FIRE(atoms, logfile=None, dt=dt, dtmax=10 * dt, maxstep=0.1 * spacing)
                else:
                    opt = LBFGS(atoms, logfile=None, maxstep=min(0.1 * spacing, 1.0), alpha=f0 / (0.01 * spacing),
                                memory=20)
                    opt.maxstep = 0.1 * spacing
                counter = {"calls": 0}

                def tick(opt=opt):
                    counter["calls"] += 1
                    if counter["calls"] % 20 == 0:
                        trace.append((counter["calls"], eps_of(atoms, calc)))

                opt.attach(tick, interval=1)
                opt.run(fmax=1e-12, steps=budget)
            tr = np.array(trace)
            rows[f"{case}:{name}"] = dict(trace=trace, eps=float(tr[-1, 1]), wall_s=time.perf_counter() - t0)
            ax.loglog(np.maximum(tr[:, 0], 1), tr[:, 1], label=name)
            print(f"(g) {case} {name}: eps {tr[-1, 1]:.2e} after {int(tr[-1, 0])} force calls", flush=True)
        ax.set_title(title)
        ax.set_xlabel("force evaluations")
        ax.set_ylabel("epsilon (Eq. 45)")
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "fig_optimizers.png", dpi=120)
    plt.close(fig)
    return rows


def pairing(quick):
    """(h) Beyond the paper: does a low eps mean a regular arrangement? Nearest-neighbour statistics of the
    uniform circle after ALARIC's dynamics, after the least-squares polish, and after WVT."""
    from scipy.spatial import cKDTree

    domain = Circle((0.0, 0.0), 1.0)
    steps = 300 if quick else 2000
    rows = {}

    def stats(name, atoms):
        x = atoms.positions[:, :2]
        nn = cKDTree(x).query(x, k=2)[0][:, 1]
        probe = ALARICCalculator(target_density=uniform_density, dim=2, domain=domain, form="log")
        copy = atoms.copy()
        copy.calc = probe
        interior = np.linalg.norm(x, axis=1) < 0.8
        rows[name] = dict(eps=eps_of(copy, probe), nn_min_over_mean=float(nn.min() / nn.mean()),
                          nn_std_over_mean=float(nn.std() / nn.mean()),
                          interior_nn_std_over_mean=float(nn[interior].std() / nn[interior].mean()))
        print(f"(h) {name}: {rows[name]}", flush=True)

    atoms = circle_start(2000)
    calc = ALARICCalculator(target_density=uniform_density, dim=2, domain=domain, form="log")
    atoms.calc = calc
    ALARICDynamics(atoms, eps_min=0.0, eps_dot_min=0.0).run(steps)
    stats(f"ALARIC, {steps} steps", atoms)
    mass = model.reset_mass(calc.results["target"], calc.results["number_density"])
    polish_least_squares(atoms, uniform_density, 2, mass, lambda x: np.zeros_like(x), domain=domain, steps=steps,
                         chunk=200)
    stats(f"ALARIC + {steps} polish steps", atoms)
    wvt = circle_start(2000)
    WVTRelaxation(wvt, uniform_density, 2, steps=steps, weight="r2", domain=domain).run()
    stats(f"WVT r^-2, {steps} steps", wvt)
    return rows


def _md_table(title, header, rows, note=None):
    """Markdown section: a title, an optional note and a table of string cells."""
    lines = [f"## {title}", ""] + ([note, ""] if note else [])
    lines += ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return lines + [""]


def write_readme(out, results):
    """``tables.md`` under ``out`` from results.json (and the tables written by parts a and b)."""
    lines = ["# Tables of `reproductions/lib/alaric_reproduce.py`", "",
             "Generated by `python reproductions/lib/alaric_reproduce.py --only PARTS --out THIS_FOLDER` "
             "(every number in `results.json`, the load average of each part in `load.txt`). Shared 2-vCPU "
             "machine, other jobs running: wall and CPU times are indicative only.", ""]
    dates = results.get("dates", {})
    if dates:
        lines += ["When each part last ran (`results.json`, `dates`; the ALARIC forces are exact since 2026-12-02 "
                  "02:10 UTC, before that Omega was floored at 0.05 in them): "
                  + ", ".join(f"{key} {when}" for key, when in sorted(dates.items())) + ".", ""]
    for name in ("table1.md", "table2.md"):
        if (out / name).exists():
            lines += [(out / name).read_text().replace("# ", "## ", 1), ""]
    r = results
    if "fig6" in r:
        lines += _md_table("Fig. 6: 909 particles, 0, 1, 2 splitting stages (`fig6.png`)",
                           ["stages", "steps", "final eps", "stop", "wall [s]"],
                           [[k, str(v["steps"]), f"{v['eps']:.2e}", v["stop"], f"{v['wall_s']:.0f}"]
                            for k, v in r["fig6"].items()])
    if "fig8" in r:
        lines += _md_table("Fig. 8: radial profiles, Eq. 46 with Delta = 0.01, N = 77 * 7^d, 3D 77 * 5^3 (`fig8.png`)",
                           ["dim", "N", "eps", "Eq. 48", "steps", "stop", "closest particle to the centre (r)",
                            "particles with r < 0.15"],
                           [[k, str(v["n"]), f"{v['eps']:.2e}", f"{v['teo']:.1e}", str(v["steps"]), v["stop"],
                             f"{v['closest_to_centre']:.3g}", str(v["particles_within_0_15"])]
                            for k, v in r["fig8"].items()])
    if "fig10_11" in r:
        lines += _md_table("Figs. 10-11: Eq. 49 in the unit disc (`fig10_11.png`)",
                           ["p", "N", "eps after the dynamics", "eps after the polish", "steps", "wall [s]"],
                           [[k, str(v["n"]), f"{v['eps_dynamics']:.2e}", f"{v['eps']:.2e}", str(v["steps"]),
                             f"{v['wall_s']:.0f}"] for k, v in r["fig10_11"].items()])
    if "fig13" in r:
        lines += _md_table("Sec. 5.1 / Fig. 13: 2000 particles, uniform density in the unit circle (`fig13.png`)",
                           ["method", "steps", "final eps", "wall [s]"],
                           [[k, str(v["steps"]), f"{v['eps']:.2e}", f"{v['wall_s']:.0f}"]
                            for k, v in r["fig13"].items()],
                           note="Paper: WVT reaches about 1e-3, ALARIC about 1e-5 (100x lower) at about 10x the cost.")
    if "optimizers" in r:
        lines += _md_table("(g) ASE optimisers on the ALARIC potential against ALARIC's dynamics "
                           "(`fig_optimizers.png`)", ["case", "driver", "final eps", "force evaluations"],
                           [k.split(":", 1) + [f"{v['eps']:.2e}", str(int(v["trace"][-1][0]))]
                            for k, v in r["optimizers"].items()])
    if "pairing" in r:
        lines += _md_table("(h) Beyond the paper: eps against the regularity of the arrangement (uniform circle, N = 2000)",
                           ["state", "eps", "min NN distance / mean", "NN std / mean", "NN std / mean (r < 0.8)"],
                           [[k, f"{v['eps']:.2e}", f"{v['nn_min_over_mean']:.3f}", f"{v['nn_std_over_mean']:.3f}",
                             f"{v['interior_nn_std_over_mean']:.3f}"] for k, v in r["pairing"].items()])
    (out / "tables.md").write_text("\n".join(lines) + "\n")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", default="a,b,c,d,e,f,g,h", help="comma-separated parts (default all)")
    parser.add_argument("--quick", action="store_true", help="smaller runs (minutes, for checking the script)")
    parser.add_argument("--deltas", default="0.1", help="part b2: the Deltas (comma-separated)")
    parser.add_argument("--out", required=True,
                        help="the entry's results folder, e.g. reproductions/alaric-table1/results")
    args = parser.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    results_path = out / "results.json"
    results = json.loads(results_path.read_text()) if results_path.exists() else {}
    parts = args.only.split(",")
    load = open(out / "load.txt", "a")

    def save(key, value):
        merged = json.loads(results_path.read_text()) if results_path.exists() else {}
        merged[key] = value
        results[key] = value
        if key != "quick":  # when each part last ran (the README says which code state its table is)
            merged.setdefault("dates", {})[key] = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
            results["dates"] = merged["dates"]
        results_path.write_text(json.dumps(merged, indent=1, default=float))

    for part in parts:
        load.write(f"{time.strftime('%H:%M:%S')} part {part} start, load {os.getloadavg()}\n")
        load.flush()
        if part == "a":
            rows, md = table1(args.quick)
            (out / "table1.md").write_text(md)
            save("table1", rows)
        elif part == "a2":
            rows, md = table1_forms(args.quick)
            folder = out / "table1_forms"
            folder.mkdir(exist_ok=True)
            command = f"python reproductions/lib/alaric_reproduce.py --only a2{' --quick' if args.quick else ''} --out {args.out}"
            (folder / "table.md").write_text(md + f"\nCommand: `{command}`; load average at the end "
                                             f"{os.getloadavg()[0]:.1f}.\n")
            (folder / "results.json").write_text(json.dumps(dict(command=command, load_average=os.getloadavg(),
                                                                 runs=rows), indent=1, default=float))
        elif part == "b2":
            table2_isolate(args.quick, out, tuple(float(d) for d in args.deltas.split(",")))
        elif part == "b":
            rows, md = table2(args.quick)
            (out / "table2.md").write_text(md)
            save("table2", rows)
        elif part == "c":
            save("fig6", fig6(args.quick, out))
        elif part == "d":
            save("fig8", fig8(args.quick, out))
        elif part == "e":
            save("fig10_11", fig10_11(args.quick, out))
        elif part == "f":
            save("fig13", fig13(args.quick, out))
        elif part == "h":
            save("pairing", pairing(args.quick))
        elif part == "g":
            save("optimizers", optimizers(args.quick, out, results.get("fig13")))
        load.write(f"{time.strftime('%H:%M:%S')} part {part} end, load {os.getloadavg()}\n")
        load.flush()
    save("quick", args.quick)
    write_readme(out, json.loads(results_path.read_text()))


if __name__ == "__main__":
    main()
