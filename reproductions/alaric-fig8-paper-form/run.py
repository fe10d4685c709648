"""Fig. 8 with the paper's force (Eq. 29 + background pressure, eta = 2.5): does a particle stay at the bottom?

Eq. 46 with Delta = 0.01 (as ``../alaric-fig8``, ``../alaric-fig8-1d``, ``../alaric-fig8-bottom``), ``form="paper"``
with the calculator's defaults (``background_pressure="deficit"``, ``eta = PAPER_ETA``), one splitting stage, no
polish, mirror ghosts at the unit disc / ball in 2D/3D (the CLI's defaults otherwise). One JSON per run,
``results/<case>.json``.

The measure, declared before the runs: the particle closest to the well's centre (r1) is **held at the bottom**
when r1 <= 0.25 s1, s1 its distance to its own nearest neighbour (the local spacing there); **no pairing** when
the smallest nearest-neighbour distance is >= 0.5 of the mean (issue 30's measure); the goal is epsilon (Eq. 45)
<= 1e-3 with both.

Cases (one ingredient changed from a control each):
  1d            N = 537 (179 split once; the particle at x = 0 starts there); control: ``../alaric-fig8-1d``
                ``no_polish`` (the log form, same start and split, r1 = 0.053).
  1d_displaced  as 1d with the particle at x = 0 moved by a quarter of the start spacing (stability, not symmetry).
  2d            N = 1000 (250 split once, the CLI's jittered start); control: ``../alaric-fig8-bottom`` (the log
                form, same N, start and step cap, r1 = 0.143).
  2d_n3772      as 2d with the paper's N (77 * 7^2 = 3773 rounded to a multiple of 4: 943 split once; the step cap
                of ``../alaric-fig8`` ``2d``, 10 000, and a 900 s wall cap).
  3d            N = 2075 (415 split once); control: ``../alaric-fig8`` ``3d_n2075`` (log, r1 = 0.236).
  3d_n9625      as 3d with N = 9625 (1925 split once; the paper's 77 l^3 with l = 5): the resolution.
  3d_n26410     as 3d with about the paper's N (77 * 7^3 = 26 411 rounded to a multiple of 5: 5282 split once), capped
                at 720 s of wall time.
  1d_log, 2d_log, 3d_log   the controls: 1d, 2d, 3d with the log form (the package's default), measured the same way.
When the particle closest to the centre is paired (s1 below 0.5 of the mean spacing), the run also measures the
force between it and its partner, pulled apart symmetrically by delta = 0.01 and 0.1 (positive: repulsive), under
the run's setting and under eta 3.0, Wendland C2 and the cubic spline (``pair_force`` in the JSON).

    python reproductions/alaric-fig8-paper-form/run.py --only 1d,1d_displaced --out reproductions/alaric-fig8-paper-form/results
"""
from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402
from scipy.spatial import cKDTree  # noqa: E402

from ase_sphrelax.analysis.alaric import alaric_min_error  # noqa: E402
from ase_sphrelax.calculators.alaric import ALARICCalculator  # noqa: E402
from ase_sphrelax.drivers.alaric_dynamics import relax_density, start_atoms  # noqa: E402
from ase_sphrelax.models import alaric as model  # noqa: E402

DELTA = 0.01
CASES = {  # dim, N, splits, step cap, wall cap (s), displace the central start particle by this many spacings, form
    "1d": (1, 537, 1, 20000, None, 0.0, "paper"),
    "1d_displaced": (1, 537, 1, 20000, None, 0.25, "paper"),
    "2d": (2, 1000, 1, 3000, None, 0.0, "paper"),
    "2d_n3772": (2, 3772, 1, 10000, 900, 0.0, "paper"),
    "3d": (3, 2075, 1, 3000, None, 0.0, "paper"),
    "3d_n9625": (3, 9625, 1, 3000, 1500, 0.0, "paper"),
    "3d_n26410": (3, 26410, 1, 3000, 720, 0.0, "paper"),
    "1d_log": (1, 537, 1, 20000, None, 0.0, "log"),  # the controls: the same runs with the log form
    "2d_log": (2, 1000, 1, 3000, None, 0.0, "log"),
    "3d_log": (3, 2075, 1, 3000, None, 0.0, "log"),
}
HELD = 0.25  # r1 <= HELD * s1
PAIRED = 0.5  # nearest neighbour below this fraction of the mean


def pair_force(atoms, calc, a, b, dim, domain):
    """Relative force along the pair axis of particles a and b, set symmetrically delta apart about their midpoint."""
    out = []
    axis = np.zeros(3)
    axis[0] = 1.0
    for label, kw in (("run", {}), ("eta 3.0", dict(eta=3.0)), ("wendland_c2", dict(kernel="wendland_c2")),
                      ("cubic_spline", dict(kernel="cubic_spline"))):
        density, gradient = model.eq46(DELTA)
        probe = ALARICCalculator(target_density=density, target_gradient=gradient, dim=dim, form="paper",
                                 domain=domain, boundary=calc.parameters.boundary, mass=calc.mass,
                                 origin=calc.origin if dim == 1 else None, **kw)
        for delta in (0.01, 0.1):
            x = atoms.copy()
            centre = 0.5 * (atoms.positions[a] + atoms.positions[b])
            x.positions[a] = centre + 0.5 * delta * axis
            x.positions[b] = centre - 0.5 * delta * axis
            x.calc = probe
            f = x.get_forces()
            out.append(dict(setting=label, delta=delta, relative_force=float(f[a, 0] - f[b, 0]),
                            h_a=float(probe.results["smoothing_lengths"][a])))
    return out


def run(case):
    dim, n, splits, cap, wall, shift, form = CASES[case]
    p = {1: 3, 2: 4, 3: 5}[dim]
    atoms, origin, domain = start_atoms(n // p**splits, dim)
    x0 = atoms.positions[:, :dim] + origin
    k = int(np.argmin(np.linalg.norm(x0, axis=1)))
    start_r1 = float(np.linalg.norm(x0[k]))
    if shift:
        atoms.positions[k, 0] += shift * float(atoms.info["dx"])
    density, gradient = model.eq46(DELTA)
    t0, c0 = time.perf_counter(), time.process_time()
    res = relax_density(atoms, density, dim, target_gradient=gradient, splits=splits, domain=domain, origin=origin,
                        form=form, polish=False, max_steps=cap, split_at_cap=True,
                        **({} if wall is None else dict(max_wall=wall)))
    calc = res["calculator"]
    atoms = res["atoms"]
    x = calc.points(atoms.positions, atoms)
    r = np.linalg.norm(x, axis=1)
    dist, idx = cKDTree(x).query(x, k=2)
    gap, partner = dist[:, 1], idx[:, 1]
    a = int(np.argmin(r))
    s1 = float(gap[a])
    row = dict(case=case, dim=dim, n=len(x), splits=splits, delta=DELTA, form=form, eta=float(calc.eta),
               background_pressure="deficit" if form == "paper" else None, boundary=calc.parameters.boundary, step_cap=cap, wall_cap_s=wall,
               start_shift_spacings=shift, start_r1=start_r1,
               steps=int(res["steps"]), stop=res["stop_reason"], epsilon=float(res["epsilon"]),
               eq48=alaric_min_error(len(x), DELTA, dim), r1=float(r[a]), s1=s1,
               r1_over_s1=float(r[a] / s1) if s1 > 0 else float("inf"),
               held=bool(r[a] <= HELD * s1), nn_min_over_mean=float(gap.min() / gap.mean()),
               paired=bool(gap.min() < PAIRED * gap.mean()), n_paired=int(np.count_nonzero(gap < PAIRED * gap.mean())),
               smallest_r=np.sort(r)[:6].tolist(), rho_r1=float(calc.results["density"][a]),
               target_r1=float(calc.results["target"][a]), h_r1=float(calc.results["smoothing_lengths"][a]),
               wall_s=time.perf_counter() - t0, cpu_s=time.process_time() - c0, load_average=list(os.getloadavg()),
               trace=[(e["step"], e["n"], e["epsilon"]) for e in res["trace"]])
    row["goal_met"] = bool(row["held"] and not row["paired"] and row["epsilon"] <= 1e-3)
    if form == "paper" and gap[a] < PAIRED * gap.mean():
        row["pair_force"] = pair_force(atoms, calc, a, int(partner[a]), dim, domain)
    return row


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default=",".join(CASES))
    ap.add_argument("--out", default="reproductions/alaric-fig8-paper-form/results")
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    for case in args.only.split(","):
        row = run(case)
        row["command"] = f"python reproductions/alaric-fig8-paper-form/run.py --only {case} --out {args.out}"
        (out / f"{case}.json").write_text(json.dumps(row, indent=1) + "\n")
        print({k: v for k, v in row.items() if k != "trace"}, flush=True)


if __name__ == "__main__":
    main()
