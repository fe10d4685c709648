"""Fig. 13 (Sec. 5.1) after the exact-force change: 2000 particles, uniform density in the unit circle, one
uniformly random start; ALARIC's dynamics with the log potential (exact Omega) and with the paper's Eq. 29 form,
against WVT (r^-2 weight). Per run: epsilon (Eq. 45 with the Eq. 44 mass), the smallest nearest-neighbour distance
over the mean (pairing), the wall time, and for ALARIC the smallest CFL step.

    python reproductions/lib/alaric_fig13_forms.py --n 2000 --steps 10000 --out reproductions/alaric-fig13-truncated/results
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from ase_sphrelax import ALARICCalculator
from ase_sphrelax.domains import Circle
from ase_sphrelax.drivers.alaric_dynamics import ALARICDynamics
from ase_sphrelax.drivers.wvt import WVTRelaxation

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from lib.alaric_reproduce import circle_start, eps_of, uniform_density  # noqa: E402 (the same start as Fig. 13 there)


def nn_ratio(atoms):
    x = atoms.positions[:, :2]
    d, _ = cKDTree(x).query(x, k=2)
    return float(d[:, 1].min() / d[:, 1].mean())


def alaric(n, steps, form, seed, boundary="wall"):
    domain = Circle((0.0, 0.0), 1.0)
    atoms = circle_start(n, seed)
    calc = ALARICCalculator(target_density=uniform_density, target_gradient=lambda x: np.zeros_like(x), dim=2,
                            domain=domain, form=form, boundary=boundary)
    atoms.calc = calc
    nn0 = nn_ratio(atoms)
    load0 = os.getloadavg()
    t0 = time.perf_counter()
    dyn = ALARICDynamics(atoms, eps_dot_min=0.0, eps_min=0.0)
    dts, walls = [], []
    dyn.attach(lambda: (dts.append(dyn.dt), walls.append(time.perf_counter() - t0)), interval=1)
    error = None
    try:
        dyn.run(steps)
    except Exception as exc:  # noqa: BLE001 - a failed run is a result
        error = f"{type(exc).__name__}: {exc}"
    wall = time.perf_counter() - t0
    loads = dict(load_average_start=load0, load_average_end=os.getloadavg())
    builds = calc.nlist.builds if calc.nlist is not None else None
    trace = [(e["step"], e["epsilon"]) for e in dyn.trace]
    reached = {f"{thr:g}": _first_below(trace, walls, thr) for thr in (1e-3, 1e-4, 1e-5)}
    eps = eps_of(atoms, calc)
    other = "wall" if boundary == "mirror" else "mirror"  # the same end state seen with the other edge treatment
    probe = ALARICCalculator(target_density=uniform_density, dim=2, domain=domain, boundary=other, form="log")
    final = atoms.copy()
    final.calc = probe
    eps_other = eps_of(final, probe)
    return dict(method=f"ALARIC ({form}, {boundary})", steps=dyn.nsteps, epsilon=eps, **{f"epsilon_{other}": eps_other},
                first_below=reached, positions=atoms.positions[:, :2].tolist(),
                nn_min_over_mean=nn_ratio(atoms),
                nn_min_over_mean_start=nn0, wall_s=wall, dt_min=float(min(dts)) if dts else None,
                dt_median=float(np.median(dts)) if dts else None, error=error, trace=trace, nlist_builds=builds,
                force_calls=dyn.force_calls, **loads)


def _first_below(trace, walls, threshold):
    """(step, wall seconds) of the first recorded epsilon <= threshold, or None."""
    for step, eps in trace:
        if eps <= threshold:
            return dict(step=int(step), wall_s=float(walls[min(step, len(walls)) - 1]) if walls else None)
    return None


def wvt(n, steps, seed):
    domain = Circle((0.0, 0.0), 1.0)
    atoms = circle_start(n, seed)
    opt = WVTRelaxation(atoms, uniform_density, 2, steps=steps, weight="r2", domain=domain)
    load0 = os.getloadavg()
    t0 = time.perf_counter()
    opt.run()
    wall = time.perf_counter() - t0
    loads = dict(load_average_start=load0, load_average_end=os.getloadavg())
    eps = {}
    for boundary in ("wall", "mirror"):  # Eq. 45 with truncated kernels, and with the mirror ghosts
        probe = ALARICCalculator(target_density=uniform_density, dim=2, domain=domain, boundary=boundary,
                                 form="log")
        atoms.calc = probe
        eps[boundary] = eps_of(atoms, probe)
    return dict(method="WVT r^-2", steps=opt.nsteps, epsilon=eps["wall"], epsilon_mirror=eps["mirror"],
                nn_min_over_mean=nn_ratio(atoms), wall_s=wall, **loads)


def wall_ratios(rows, command):
    """Each ALARIC run's wall time over the first WVT run's (the same run, back to back), as written to
    ``wall_ratio.json``; ``wall_ratio`` alone when there is one ALARIC run."""
    base = next(r for r in rows if r["method"].startswith("WVT"))
    ratios = {r["method"]: r["wall_s"] / base["wall_s"] for r in rows if r is not base}
    out = dict(command=command, wvt=base["method"], wall_ratio_by_method=ratios)
    if len(ratios) == 1:
        out["wall_ratio"] = next(iter(ratios.values()))
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=2000)
    ap.add_argument("--steps", type=int, default=10000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--forms", default="log,paper")
    ap.add_argument("--boundaries", default="wall", help="comma-separated: wall, mirror (each form with each)")
    ap.add_argument("--no-wvt", action="store_true", help="skip the WVT baseline")
    ap.add_argument("--out", default="reproductions/alaric-fig13-truncated/results")
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    command = (f"python reproductions/lib/alaric_fig13_forms.py --n {args.n} --steps {args.steps} --seed {args.seed} "
               f"--forms {args.forms} --boundaries {args.boundaries}{' --no-wvt' if args.no_wvt else ''} "
               f"--out {args.out}")
    # warm-up (numba compiles on first use): the timed runs below measure the steps, not the compilation
    wvt(200, 3, args.seed)
    for boundary in args.boundaries.split(","):
        alaric(200, 3, args.forms.split(",")[0], args.seed, boundary)
    rows = []
    if not args.no_wvt:
        rows.append(wvt(args.n, args.steps, args.seed))
        print(rows[-1], flush=True)
    for boundary in args.boundaries.split(","):
        for form in args.forms.split(","):
            rows.append(alaric(args.n, args.steps, form, args.seed, boundary))
            print({k: v for k, v in rows[-1].items() if k not in ("trace", "positions")}, flush=True)
    load = os.getloadavg()
    (out / "results.json").write_text(json.dumps(dict(command=command, load_average=load, runs=rows), indent=1))
    lines = [f"N = {args.n}, {args.steps} steps, seed {args.seed}. Command: `{command}`. Load average at the end "
             f"{load[0]:.1f} on 2 vCPUs (wall times indicative only).", "",
             "| method | steps | eps | min NN / mean NN | wall s | load avg start / end | note |",
             "|---|---|---|---|---|---|---|"]
    for r in rows:
        note = r.get("error") or (f"dt min {r['dt_min']:.2e}, median {r['dt_median']:.2e}" if r.get("dt_min") else "")
        if "epsilon_mirror" in r:
            note = f"eps with mirror ghosts {r['epsilon_mirror']:.2e}"
        if "epsilon_wall" in r:
            note += f"; eps with truncated kernels {r['epsilon_wall']:.2e}"
        if r.get("first_below"):
            note += "; first eps <= " + ", ".join(f"{k}: step {v['step']} ({v['wall_s']:.0f} s)"
                                                 for k, v in r["first_below"].items() if v)
        lines.append(f"| {r['method']} | {r['steps']} | {r['epsilon']:.2e} | {r['nn_min_over_mean']:.3f} | "
                     f"{r['wall_s']:.0f} | {r['load_average_start'][0]:.1f} / {r['load_average_end'][0]:.1f} | {note} |")
    wvt_rows = [r for r in rows if r["method"].startswith("WVT")]
    if wvt_rows:
        lines.append("")
        lines += [f"{r['method']}: wall time {r['wall_s'] / wvt_rows[0]['wall_s']:.1f}x WVT's (same run, back to back; "
                  f"threads: NUMBA_NUM_THREADS={os.environ.get('NUMBA_NUM_THREADS', 'unset')})"
                  for r in rows if r is not wvt_rows[0]]
    (out / "table.md").write_text("\n".join(lines) + "\n")
    if wvt_rows:
        (out / "wall_ratio.json").write_text(json.dumps(wall_ratios(rows, command), indent=1) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
