"""Fig. 13 (ALARIC Sec. 5.1) on the measure declared in README.md before the run (issue 30 item 4).

2000 particles, uniform density in the unit circle, one uniformly random start (seed 0). WVT r^-2 with mirror
ghosts under the linear and Diehl's schedules, ALARIC (log form, paper form) with mirror ghosts; every state
measured by ``ase_sphrelax.analysis.alaric.declared_epsilon`` (Eq. 45 over all particles, mirror ghosts, Eq. 44
mass). Then, as a diagnostic, WVT without ghosts under both schedules (also on truncated kernels).

    OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 python reproductions/alaric-fig13-declared/run.py \
        --out reproductions/alaric-fig13-declared/results
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from ase_sphrelax import ALARICCalculator
from ase_sphrelax.analysis.alaric import declared_epsilon, nn_min_over_mean
from ase_sphrelax.domains import Circle
from ase_sphrelax.drivers.alaric_dynamics import ALARICDynamics
from ase_sphrelax.drivers.wvt import WVTRelaxation

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from lib.alaric_reproduce import circle_start, uniform_density  # noqa: E402 (the start of every Fig. 13 entry)

DOMAIN = Circle((0.0, 0.0), 1.0)


def checkpoints(steps):
    early = [1, 2, 3, 5, 7, 10, 15, 20, 30, 50, 70]
    return sorted({s for s in early if s <= steps} | set(range(100, steps + 1, 100)) | {steps})


class Recorder:
    """Positions, wall and CPU time (the recorder's own time left out) at the checkpoint steps."""

    def __init__(self, driver, atoms, steps):
        self.driver, self.atoms, self.marks = driver, atoms, set(checkpoints(steps))
        self.rows, self.own = [], 0.0
        self.t0 = self.c0 = None

    def start(self):
        self.t0, self.c0 = time.perf_counter(), time.process_time()

    def __call__(self, force=False):
        t = time.perf_counter()
        step = int(self.driver.nsteps)
        if (step in self.marks or force) and (not self.rows or self.rows[-1][0] != step):
            self.rows.append((step, t - self.t0 - self.own, time.process_time() - self.c0 - self.own,
                              self.atoms.positions[:, :2].copy()))
        self.own += time.perf_counter() - t

    def measured(self, boundaries=("mirror",)):
        out = []
        for step, wall, cpu, x in self.rows:
            row = dict(step=step, wall_s=wall, cpu_s=cpu)
            for b in boundaries:
                key = "epsilon" if b == "mirror" else f"epsilon_{b}"
                row[key] = declared_epsilon(x, uniform_density, DOMAIN, 2, b)["epsilon"]
            out.append(row)
        return out


def run_wvt(n, steps, seed, schedule, boundary, boundaries=("mirror",), mu0=None):
    atoms = circle_start(n, seed)
    opt = WVTRelaxation(atoms, uniform_density, 2, steps=steps, weight="r2", domain=DOMAIN, schedule=schedule,
                        boundary=boundary, mu0=mu0)
    rec = Recorder(opt, atoms, steps)
    opt.attach(rec, interval=1)
    load0 = os.getloadavg()
    rec.start()
    opt.run()
    rec(force=True)
    wall, cpu = rec.rows[-1][1], rec.rows[-1][2]
    x = atoms.positions[:, :2]
    trace = rec.measured(boundaries)
    name = f"WVT r^-2 ({schedule}, {boundary}{'' if mu0 is None else f', mu0 {mu0:g}'})"
    return dict(method=name, kind="wvt", schedule=schedule, boundary=boundary, mu0=float(opt.mu0),
                steps=int(opt.nsteps), stopped_by_schedule=bool(opt.stopped), mu_end=float(opt.mu),
                epsilon=trace[-1]["epsilon"], **{f"epsilon_{b}": trace[-1][f"epsilon_{b}"] for b in boundaries
                                                if b != "mirror"},
                nn_min_over_mean=nn_min_over_mean(x), wall_s=wall, cpu_s=cpu, load_average_start=load0,
                load_average_end=os.getloadavg(), trace=trace)


def run_alaric(n, steps, seed, form):
    atoms = circle_start(n, seed)
    calc = ALARICCalculator(target_density=uniform_density, target_gradient=lambda x: np.zeros_like(x), dim=2,
                            domain=DOMAIN, form=form, boundary="mirror")
    atoms.calc = calc
    dyn = ALARICDynamics(atoms, eps_dot_min=0.0, eps_min=0.0)
    rec = Recorder(dyn, atoms, steps)
    dyn.attach(rec, interval=1)
    load0 = os.getloadavg()
    error = None
    rec.start()
    try:
        dyn.run(steps)
    except Exception as exc:  # noqa: BLE001 - a failed run is a result
        error = f"{type(exc).__name__}: {exc}"
    rec(force=True)
    wall, cpu = rec.rows[-1][1], rec.rows[-1][2]
    trace = rec.measured()
    p = calc.parameters
    return dict(method=f"ALARIC ({form}, mirror)", kind="alaric", form=form, boundary="mirror", steps=int(dyn.nsteps),
                eta=calc.eta, background_pressure=p.background_pressure, error=error,
                epsilon=trace[-1]["epsilon"], nn_min_over_mean=nn_min_over_mean(atoms.positions[:, :2]),
                wall_s=wall, cpu_s=cpu, load_average_start=load0, load_average_end=os.getloadavg(), trace=trace)


def goal(alaric, wvt, clock="wall_s"):
    """ALARIC's epsilon at its last checkpoint within 10x WVT's time, and WVT's final over it."""
    budget = 10.0 * wvt[clock]
    within = [r for r in alaric["trace"] if r[clock] <= budget]
    at = within[-1] if within else None
    ratio = wvt["epsilon"] / at["epsilon"] if at else None
    return dict(alaric=alaric["method"], wvt=wvt["method"], clock=clock, budget_s=budget,
                alaric_step=at["step"] if at else None, alaric_epsilon=at["epsilon"] if at else None,
                wvt_epsilon=wvt["epsilon"], ratio=ratio, met=bool(ratio is not None and ratio >= 10.0),
                final_ratio=wvt["epsilon"] / alaric["epsilon"], final_time_ratio=alaric[clock] / wvt[clock])


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=2000)
    ap.add_argument("--steps", type=int, default=10000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--no-diagnostic", action="store_true", help="skip the WVT runs without ghosts")
    ap.add_argument("--out", default="reproductions/alaric-fig13-declared/results")
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    command = (f"python reproductions/alaric-fig13-declared/run.py --n {args.n} --steps {args.steps} --seed {args.seed}"
               f"{' --no-diagnostic' if args.no_diagnostic else ''} --out {args.out}")
    threads = dict(OMP_NUM_THREADS=os.environ.get("OMP_NUM_THREADS"), NUMBA_NUM_THREADS=os.environ.get(
        "NUMBA_NUM_THREADS"))
    # warm-up: numba compiles on first use; the timed runs measure steps, not compilation
    for schedule in ("linear", "diehl"):
        for boundary in ("mirror", "project"):
            run_wvt(200, 3, args.seed, schedule, boundary, ("mirror", "wall"))
    for form in ("log", "paper"):
        run_alaric(200, 3, args.seed, form)
    start = dict(epsilon=declared_epsilon(circle_start(args.n, args.seed).positions, uniform_density, DOMAIN, 2)[
        "epsilon"], nn_min_over_mean=nn_min_over_mean(circle_start(args.n, args.seed).positions[:, :2]))
    runs = []

    def save():
        wvts = [r for r in runs if r["kind"] == "wvt" and r["boundary"] == "mirror"]
        goals = [goal(a, w, c) for a in runs if a["kind"] == "alaric" for w in wvts for c in ("wall_s", "cpu_s")]
        data = dict(command=command, threads=threads, n=args.n, seed=args.seed, start=start, runs=runs, goals=goals)
        (out / "results.json").write_text(json.dumps(data, indent=1) + "\n")
        return goals

    for schedule in ("linear", "diehl"):
        runs.append(run_wvt(args.n, args.steps, args.seed, schedule, "mirror"))
        print({k: v for k, v in runs[-1].items() if k != "trace"}, flush=True)
        save()
    for form in ("log", "paper"):
        runs.append(run_alaric(args.n, args.steps, args.seed, form))
        print({k: v for k, v in runs[-1].items() if k != "trace"}, flush=True)
        save()
    if not args.no_diagnostic:
        for schedule in ("linear", "diehl"):
            runs.append(run_wvt(args.n, args.steps, args.seed, schedule, "project", ("mirror", "wall")))
            print({k: v for k, v in runs[-1].items() if k != "trace"}, flush=True)
            save()
    for g in save():
        print(g, flush=True)
    plot(runs, out / "fig13.png")


def plot(runs, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from ase_sphrelax.plotting import save_figure

    fig, ax = plt.subplots(figsize=(6, 4))
    for r in runs:
        steps = [t["step"] for t in r["trace"]]
        ax.loglog(steps, [t["epsilon"] for t in r["trace"]], label=r["method"],
                  ls="-" if r["boundary"] == "mirror" else ":")
    ax.set_xlabel("steps")
    ax.set_ylabel("epsilon (Eq. 45, mirror ghosts, all particles)")
    ax.legend(fontsize=7)
    fig.tight_layout()
    save_figure(fig, path, dpi=90, colors=64)


if __name__ == "__main__":
    main()
