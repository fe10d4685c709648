"""Table 1's F run instrumented, then one ingredient changed at a time (issue 20 item 2).

The F run: friction chi = 2 only (no velocity stops, no viscosity), log potential, Eq. 46 with Delta = 0, 300
equispaced particles on the periodic [-1, 1), cap 10 000 steps (as ``reproductions/lib/alaric_reproduce.py`` part a and
``reproductions/alaric-table1-f/f_run.py``). An observer of the public driver (``dyn.attach``) records after every
step: the step just taken ``dt``; the two limits of the next step (signal speed ``C min H/(v_sig + |v|max)`` and force
``C min sqrt(H/|a|)``) and which one is smaller (the driver's ``cfl_timestep`` takes their minimum: checked against the
next ``dt``); the smallest pair distance over the mean spacing 2/N and the pair; how many neighbours in the start's
order have crossed (1D: a negative gap in index order); the smallest Omega (Eq. 13), the smallest H over the mean
spacing and max |a|; epsilon (Eq. 45 with the current mass); the particle that sets the force limit with its Omega
and gap; the potential U and kinetic energy K (with friction and viscosity only, U + K can only fall over a step that
ends no interval: a rise is integration error).

Variants (``--variant``; one ingredient changed against ``F``):

* ``F``: as Table 1 (C = 0.25).
* ``F_floor``: the forces with Omega floored at 0.05 (the package before issue 20 item 1), through a subclass of
  the calculator; everything else the package in PYTHONPATH.
* ``F_C0.1``, ``F_C0.05``: a smaller Courant factor.
* ``S+F``: velocity stops added.   ``V+F``: viscosity added.

Per-step rows go to ``OUT/NAME.csv.gz``, the summary (with the rows around the smallest step) to ``OUT/NAME.json``::

    OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 nice -n 10 python reproductions/alaric-table1-f/run.py \\
        --variant F --out reproductions/alaric-table1-f/results/isolate [--steps 10000] [--name NAME]

``--perturb P --seed S`` moves each start position by P times the mean spacing times a standard normal number (the
repeats in ``table1_F/perturbed``, with ``--no-csv``); ``--summarize DIR`` writes ``DIR/table.md`` from its JSONs.

The same script runs with an older package (``git archive REV ase_sphrelax | tar -x -C /tmp/REV`` and
``PYTHONPATH=/tmp/REV``): it uses only ``start_atoms``, ``eq46``, the calculator's results and the driver's observers.
"""
from __future__ import annotations

import argparse
import gzip
import json
import os
import time
from pathlib import Path

import numpy as np

import ase_sphrelax
from ase_sphrelax import ALARICCalculator
from ase_sphrelax.drivers.alaric_dynamics import ALARICDynamics, start_atoms
from ase_sphrelax.models import alaric as model

N_PARTICLES = 300
PERIOD = 2.0
OMEGA_FLOOR_OLD = 0.05  # OMEGA_MIN of the package before issue 20 item 1

VARIANTS = {
    "F": dict(velocity_stop=False, friction=2.0, viscosity=False, cfl=0.25),
    "F_floor": dict(velocity_stop=False, friction=2.0, viscosity=False, cfl=0.25),
    "F_C0.1": dict(velocity_stop=False, friction=2.0, viscosity=False, cfl=0.1),
    "F_C0.05": dict(velocity_stop=False, friction=2.0, viscosity=False, cfl=0.05),
    "S+F": dict(velocity_stop=True, friction=2.0, viscosity=False, cfl=0.25),
    "V+F": dict(velocity_stop=False, friction=2.0, viscosity=True, cfl=0.25),
}
COLUMNS = ["step", "dt", "time", "dt_signal_next", "dt_force_next", "force_sets_next", "gap_min", "gap_pair",
           "crossed", "omega_min", "acc_max", "epsilon", "force_particle", "force_particle_omega",
           "force_particle_gap", "speed_max", "potential", "kinetic", "check",
           "h_min"]


class FlooredOmegaCalculator(ALARICCalculator):
    """The log potential's forces with ``max(Omega, 0.05)``, as before issue 20 item 1 (no longer -grad U)."""

    def _forces(self, r_pc, x_pd, state, *args, **kwargs):
        from ase_sphrelax import sph

        floored = sph.DensitySums(state.h_p, state.rho_p, state.n_p, np.maximum(state.omega_p, OMEGA_FLOOR_OLD),
                                  state.neighbours_p, state.iterations)
        return super()._forces(r_pc, x_pd, floored, *args, **kwargs)


def gaps(x_p):
    """(sorted gaps with the periodic one, the index-order gaps): pair distances along the periodic line."""
    xs = np.sort(np.mod(x_p, PERIOD))
    sorted_gaps = np.diff(np.r_[xs, xs[0] + PERIOD])
    order_gaps = np.diff(np.r_[x_p, x_p[0] + PERIOD])  # start order = index order (equispaced start)
    return sorted_gaps, order_gaps


def run(variant, steps, perturb=0.0, seed=0):
    """One run: (summary dict, per-step rows (steps + 1, len(COLUMNS))). ``perturb``: the start's positions moved by
    ``perturb`` times the mean spacing times a standard normal number each (seed ``seed``), 0 for Table 1's start."""
    atoms, origin, _ = start_atoms(N_PARTICLES, 1)
    if perturb:
        atoms.positions[:, 0] += perturb * (PERIOD / N_PARTICLES) * np.random.default_rng(seed).standard_normal(
            N_PARTICLES)
    density, gradient = model.eq46(0.0)
    cls = FlooredOmegaCalculator if variant == "F_floor" else ALARICCalculator
    atoms.calc = cls(target_density=density, target_gradient=gradient, dim=1, origin=origin, form="log")
    dyn = ALARICDynamics(atoms, **VARIANTS[variant])
    spacing = PERIOD / N_PARTICLES
    rows = []

    def limits():
        res = dyn.calc.results
        h_p = res["smoothing_lengths"]
        v_p = np.abs(atoms.get_velocities()[:, 0])
        a_p = np.abs(dyn._accel[:, 0])
        speed = float(v_p.max())
        dt_signal = dyn.cfl * float((h_p / (max(dyn.cs, speed) + speed)).min())
        with np.errstate(divide="ignore"):
            t_force = np.where(a_p > 0, np.sqrt(h_p / np.where(a_p > 0, a_p, 1.0)), np.inf)
        k = int(np.argmin(t_force))
        return dt_signal, dyn.cfl * float(t_force[k]), k, speed, float(a_p.max())

    def record(step, dt):
        res = dyn.calc.results
        x_p = atoms.positions[:, 0]
        sorted_gaps, order_gaps = gaps(x_p)
        own_gap = np.minimum(np.abs(order_gaps), np.abs(np.roll(order_gaps, 1)))  # to its start-order neighbours
        dt_signal, dt_force, k, speed, acc = limits()
        j = int(np.argmin(sorted_gaps))
        v_p = atoms.get_velocities()[:, 0]
        kinetic = 0.5 * dyn.calc.mass * float(v_p @ v_p)
        check = int(bool(dyn.trace) and dyn.trace[-1]["step"] == step)  # an interval ended: stop and/or mass reset
        rows.append([step, dt, dyn.time, dt_signal, dt_force, int(dt_force < dt_signal),
                     float(sorted_gaps[j]) / spacing, j, int((order_gaps <= 0).sum()), float(res["omega"].min()), acc,
                     float(res["epsilon"]), k, float(res["omega"][k]), float(own_gap[k]) / spacing, speed,
                     float(res["energy"]), kinetic, check, float(res["smoothing_lengths"].min()) / spacing])

    record(0, 0.0)
    dyn.attach(lambda: record(dyn.nsteps + 1, dyn.dt), interval=1)
    load0 = os.getloadavg()
    c0 = time.process_time()
    error = None
    try:
        dyn.run(steps)
    except Exception as exc:  # noqa: BLE001 - a failed run is a result
        error = f"{type(exc).__name__}: {exc}"
    cpu = time.process_time() - c0
    r = np.array(rows, dtype=float)
    col = {c: r[:, i] for i, c in enumerate(COLUMNS)}
    # the driver's dt is min(limits) of the state after the previous step: check the recorded limits against it
    dt_pred = np.minimum(col["dt_signal_next"][:-1], col["dt_force_next"][:-1])
    dt_mismatch = float(np.max(np.abs(col["dt"][1:] / dt_pred - 1))) if len(r) > 1 else 0.0
    dt = col["dt"][1:]
    i_min = int(np.argmin(dt)) + 1
    window = [dict(zip(COLUMNS, row.tolist())) for row in r[max(0, i_min - 5): i_min + 3]]
    force_sets = col["force_sets_next"][:-1]
    # energy bookkeeping: friction and viscosity only remove energy, so a rise of U + K over a step that ends no
    # interval (no velocity stop, no Eq. 44 mass reset, which change U + K by themselves) is integration error
    e_total = col["potential"] + col["kinetic"]
    d_e = np.diff(e_total)
    plain = col["check"][1:] == 0
    rise = np.where(plain & (d_e > 0), d_e, 0.0)
    close = np.minimum(col["omega_min"][:-1], col["omega_min"][1:]) < 0.05
    i_rise = int(np.argmax(rise)) + 1
    energy = dict(
        initial=float(e_total[0]), final=float(e_total[-1]), kinetic_initial=float(col["kinetic"][0]),
        rise_total=float(rise.sum()), rise_steps=int((rise > 0).sum()),
        rise_total_at_omega_below_0p05=float(rise[close].sum()), steps_at_omega_below_0p05=int(close.sum()),
        largest_rise=float(rise.max()), step_of_largest_rise=i_rise,
        rows_around_largest_rise=[dict(zip(COLUMNS, row.tolist())) for row in r[max(0, i_rise - 4): i_rise + 3]])
    summary = dict(
        variant=variant, settings=VARIANTS[variant], perturb=perturb, seed=seed, package=str(ase_sphrelax.__file__),
        steps=dyn.nsteps,
        stop=dyn.stop_reason, error=error, eps=float(col["epsilon"][-1]),
        eps_last_check=dyn.trace[-1]["epsilon"] if dyn.trace else None, time=float(dt.sum()),
        dt_min=float(dt.min()), dt_median=float(np.median(dt)), step_of_dt_min=i_min,
        fraction_force_sets_dt=float(force_sets.mean()),
        fraction_force_sets_dt_by_quarter=[float(q.mean()) for q in np.array_split(force_sets, 4)],
        gap_min_over_spacing=float(col["gap_min"].min()), step_of_gap_min=int(col["step"][np.argmin(col["gap_min"])]),
        crossed_max=int(col["crossed"].max()), first_step_crossed=(int(col["step"][np.argmax(col["crossed"] > 0)])
                                                                   if np.any(col["crossed"] > 0) else None),
        omega_min=float(col["omega_min"].min()), h_min_over_spacing=float(col["h_min"].min()),
        h_start_over_spacing=float(col["h_min"][0]), acc_max=float(col["acc_max"].max()),
        steps_with_gap_below={f"{g:g}": int((col["gap_min"] < g).sum()) for g in (0.5, 0.1, 0.01)},
        steps_with_omega_below={f"{w:g}": int((col["omega_min"] < w).sum()) for w in (0.5, 0.05, 0.01)},
        energy=energy, speed_max_by_quarter=[float(q.max()) for q in np.array_split(col["speed_max"][1:], 4)],
        dt_recorded_vs_limits_max_relative_mismatch=dt_mismatch, rows_around_dt_min=window,
        trace=[(e["step"], e["time"], e["epsilon"]) for e in dyn.trace], cpu_s=cpu,
        load_average_start=load0, load_average_end=os.getloadavg())
    return summary, r


def summarize(folder):
    """``folder/table.md``: one row per summary JSON there (the perturbed-start repeats)."""
    folder = Path(folder)
    lines = ["| file | variant | perturb, seed | steps | stop | eps (last check) | simulated time | dt min | "
             "crossed pairs | smallest gap / spacing | smallest Omega | U + K rises (at Omega < 0.05) | CPU s |",
             "|---" * 13 + "|"]
    runs = [json.loads(f.read_text()) | dict(file=f.name) for f in sorted(folder.glob("*.json"))]
    runs.sort(key=lambda d: (d["variant"], d["seed"]))
    for d in runs:
        e = d["energy"]
        lines.append(f"| `{d['file']}` | {d['variant']} | {d['perturb']:g}, {d['seed']} | {d['steps']} | {d['stop']} | "
                     f"{d['eps_last_check']:.3g} | {d['time']:.3g} | {d['dt_min']:.2g} | {d['crossed_max']} | "
                     f"{d['gap_min_over_spacing']:.2g} | {d['omega_min']:.2g} | {e['rise_total']:.3g} "
                     f"({e['rise_total_at_omega_below_0p05']:.3g}) | {d['cpu_s']:.0f} |")
    for variant in sorted({d["variant"] for d in runs}):
        of = [d for d in runs if d["variant"] == variant]
        ok = [d["steps"] for d in of if d["stop"] in ("epsilon", "epsilon_dot")]
        lines.append(f"\n{variant}: {len(ok)} of {len(of)} converged" + (f" (steps {min(ok)}-{max(ok)})" if ok else ""))
    (folder / "table.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--summarize", default=None, metavar="DIR", help="only write DIR/table.md from DIR/*.json")
    ap.add_argument("--variant", choices=sorted(VARIANTS), default="F")
    ap.add_argument("--steps", type=int, default=10000)
    ap.add_argument("--perturb", type=float, default=0.0, help="start positions moved by this times the spacing "
                    "times a standard normal number (0: Table 1's equispaced start)")
    ap.add_argument("--seed", type=int, default=0, help="seed of --perturb")
    ap.add_argument("--no-csv", action="store_true", help="write the summary only")
    ap.add_argument("--name", default=None, help="file stem (default: the variant)")
    ap.add_argument("--out", default="reproductions/alaric-table1-f/results/isolate")
    args = ap.parse_args()
    if args.summarize:
        summarize(args.summarize)
        return
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    name = args.name or args.variant
    summary, rows = run(args.variant, args.steps, args.perturb, args.seed)
    summary["command"] = (f"OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 PYTHONPATH={os.environ.get('PYTHONPATH', '')} "
                          f"python reproductions/alaric-table1-f/run.py --variant {args.variant} --steps {args.steps} "
                          f"--perturb {args.perturb} --seed {args.seed}{' --no-csv' if args.no_csv else ''} "
                          f"--name {name} --out {args.out}")
    (out / f"{name}.json").write_text(json.dumps(summary, indent=1))
    if not args.no_csv:
        with gzip.open(out / f"{name}.csv.gz", "wt") as fh:
            fh.write(",".join(COLUMNS) + "\n")
            for row in rows:
                fh.write(",".join(f"{v:.6g}" for v in row) + "\n")
    print(json.dumps({k: v for k, v in summary.items() if k not in ("rows_around_dt_min", "trace")}))


if __name__ == "__main__":
    main()
