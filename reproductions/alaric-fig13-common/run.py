"""Fig. 13's final particle sets (ALARIC with mirror ghosts, WVT) measured on common measures (issue 20 item 2).

ALARIC's 4.6e-6 is Eq. 45 with mirror ghosts at the circle, WVT's 3.3e-3 Eq. 45 with truncated kernels. Here every
final set is measured with every measure, with one construction each (the same calculator, H solve and Eq. 44 mass
for all sets):

* ``truncated``: Eq. 45 over all particles, densities cut at the circle (``ALARICCalculator(boundary="wall")``).
* ``mirror``: Eq. 45 over all particles with the mirror ghosts of ALARIC's run (``boundary="mirror"``: the same ghost
  construction and H solve ALARIC's summary uses).
* ``interior``: Eq. 45 over the particles whose support lies inside the circle (``|x_a| + H_a <= 1``): no edge
  treatment enters their density (a ghost lies outside the circle, farther than ``H_a``; checked: the truncated and
  mirror densities of these particles agree), with the Eq. 44 mass over that subset (``interior``) and with the
  physical mass ``m = rho* pi / N`` (``interior_m_phys``).
* ``integral``: the integral form of Eq. 45 (the paper's definition, left-hand side) on a square grid over the disc
  ``|r| <= 1 - max H``, ``rho(r) = m sum_b W(|r - r_b|, H_b)`` (scatter, the truncated calculator's H), with the
  mass that minimises it (``integral``) and with ``m = rho* pi / N`` (``integral_m_phys``).

Also the smallest nearest-neighbour distance over the mean (pairing) and the particle counts in the interior set.

Sets: ALARIC (log, mirror, 10 000 steps) from ``reproductions/alaric-fig13/results/results.json`` (stored positions), WVT r^-2 and WVT
kernel re-run here from the same random start (seed 0, 10 000 steps; WVT's final particles were not stored), and
the CLI's default-start ALARIC run ``reproductions/alaric-fig13-cli/results/default/relaxed.extxyz`` (run ``sh reproductions/alaric-fig13-cli/run.sh`` first: not committed) (another start: a 256-gon edge file).

    OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 nice -n 10 python reproductions/alaric-fig13-common/run.py \\
        --out reproductions/alaric-fig13-common/results
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np
from ase import Atoms
from ase.io import read
from scipy.spatial import cKDTree

from ase_sphrelax import ALARICCalculator
from ase_sphrelax.domains import Circle
from ase_sphrelax.drivers.wvt import WVTRelaxation
from ase_sphrelax.models import alaric as model

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from lib.alaric_reproduce import circle_start, uniform_density  # noqa: E402 (Fig. 13's start)

RESULTS = Path(__file__).resolve().parents[1]  # reproductions/
N = 2000
GRID_PER_SPACING = 8  # grid points per mean particle spacing along an axis (integral measure)


def nn_ratio(x_pd):
    d, _ = cKDTree(x_pd).query(x_pd, k=2)
    return float(d[:, 1].min() / d[:, 1].mean())


def probe(x_pd, boundary):
    """A fresh calculator on the set: (density, number density, target, H), H solved from scratch."""
    atoms = Atoms(numbers=np.zeros(len(x_pd), int), positions=np.c_[x_pd, np.zeros(len(x_pd))], pbc=False)
    calc = ALARICCalculator(target_density=uniform_density, dim=2, domain=Circle((0.0, 0.0), 1.0), boundary=boundary,
                            form="log")
    atoms.calc = calc
    atoms.get_forces()
    r = calc.results
    return (np.array(r["density"]), np.array(r["number_density"]), np.array(r["target"]),
            np.array(r["smoothing_lengths"]), calc.kernel)


def eq45(n_p, target_p, mass=None):
    """Eq. 45 with the Eq. 44 mass (or the given one)."""
    m = model.reset_mass(target_p, n_p) if mass is None else mass
    return model.epsilon(m * n_p, target_p, n_p)


def integral_eps(x_pd, h_p, kernel, radius):
    """Eq. 45's integral form on a grid over ``|r| <= radius``: (best-mass value, value with m = pi / N)."""
    spacing = np.sqrt(np.pi / len(x_pd))
    step = spacing / GRID_PER_SPACING
    g = np.arange(-radius, radius + step, step)
    gx, gy = np.meshgrid(g, g)
    grid = np.c_[gx.ravel(), gy.ravel()]
    grid = grid[np.hypot(grid[:, 0], grid[:, 1]) <= radius]
    pairs = cKDTree(grid).sparse_distance_matrix(cKDTree(x_pd), float(h_p.max()), output_type="coo_matrix")
    keep = pairs.data < h_p[pairs.col]
    s_g = np.bincount(pairs.row[keep], weights=kernel.w(pairs.data[keep], h_p[pairs.col[keep]]), minlength=len(grid))
    target_g = np.ones(len(grid))
    m_best = float(s_g @ target_g / (s_g @ s_g))  # minimises sum (m s - rho*)^2
    m_phys = np.pi / len(x_pd)
    value = [float(np.sum((m * s_g - target_g) ** 2) / np.sum(target_g**2)) for m in (m_best, m_phys)]
    return value[0], value[1], len(grid), m_best


def measure(name, x_pd, note):
    rho_w, n_w, t_w, h_w, kernel = probe(x_pd, "wall")
    rho_m, n_m, t_m, h_m, _ = probe(x_pd, "mirror")
    inside = np.hypot(x_pd[:, 0], x_pd[:, 1]) + h_w <= 1.0
    agree = float(np.max(np.abs(n_w[inside] / n_m[inside] - 1))) if np.any(inside) else None
    m_phys = np.pi / len(x_pd)
    radius = 1.0 - float(h_w.max())
    integ, integ_phys, n_grid, m_int = integral_eps(x_pd, h_w, kernel, radius)
    r = np.hypot(x_pd[:, 0], x_pd[:, 1])
    return dict(set=name, note=note, n=len(x_pd), nn_min_over_mean=nn_ratio(x_pd),
                truncated=eq45(n_w, t_w), mirror=eq45(n_m, t_m),
                interior=eq45(n_w[inside], t_w[inside]), interior_m_phys=eq45(n_w[inside], t_w[inside], m_phys),
                integral=integ, integral_m_phys=integ_phys,
                interior_particles=int(inside.sum()), interior_truncated_vs_mirror_max_rel_diff=agree,
                integral_radius=radius, integral_grid_points=n_grid, integral_best_mass_over_m_phys=m_int / m_phys,
                h_mean=float(h_w.mean()), h_max=float(h_w.max()),
                edge_distance_min=float(1.0 - r.max()), edge_particles_within_0p1_spacing=int(
                    np.sum(1.0 - r < 0.1 * np.sqrt(np.pi / len(x_pd)))))


def run_wvt(weight, steps, seed):
    atoms = circle_start(N, seed)
    t0 = time.perf_counter()
    opt = WVTRelaxation(atoms, uniform_density, 2, steps=steps, weight=weight, domain=Circle((0.0, 0.0), 1.0))
    opt.run()
    return atoms.positions[:, :2].copy(), opt.nsteps, time.perf_counter() - t0


def ratios(rows, keys):
    """Each set's measure over the first set's (ALARIC, mirror) per measure in ``keys`` (> 1: ALARIC lower), as the
    table's "ratio to" rows and ``ratios.json``."""
    ref = rows[0]
    return dict(ratio_to=ref["set"], rows=[dict(set=r["set"], **{k: r[k] / ref[k] for k in keys}) for r in rows])


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=10000, help="WVT steps")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default="reproductions/alaric-fig13-common/results")
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    command = (f"OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 python reproductions/alaric-fig13-common/run.py --steps "
               f"{args.steps} --seed {args.seed} --out {args.out}")
    load0 = os.getloadavg()
    sets = []
    stored = json.loads((RESULTS / "alaric-fig13" / "results" / "results.json").read_text())
    alaric = [r for r in stored["runs"] if r["method"].startswith("ALARIC")][0]
    sets.append(("ALARIC (log, mirror)", np.array(alaric["positions"]),
                 f"fig13_mirror/results.json, {alaric['steps']} steps, its own eps {alaric['epsilon']:.3g}"))
    wvt_positions = {}
    for weight in ("r2", "kernel"):
        x_pd, steps, wall = run_wvt(weight, args.steps, args.seed)
        wvt_positions[weight] = x_pd.tolist()
        sets.append((f"WVT {'r^-2' if weight == 'r2' else 'kernel'}", x_pd,
                     f"re-run here, seed {args.seed}, {steps} steps, {wall:.0f} s"))
    # written by sh reproductions/alaric-fig13-cli/run.sh (not committed): run that entry first
    cli = read(RESULTS / "alaric-fig13-cli" / "results" / "default" / "relaxed.extxyz")
    sets.append(("ALARIC, CLI default start", cli.positions[:, :2],
                 f"fig13_cli/default/relaxed.extxyz (another start; 256-gon edge file), its own eps "
                 f"{cli.info.get('epsilon', float('nan')):.3g}"))
    rows = []
    for name, x_pd, note in sets:
        rows.append(measure(name, x_pd, note))
        print(json.dumps(rows[-1]), flush=True)
    load1 = os.getloadavg()
    (out / "results.json").write_text(json.dumps(dict(command=command, load_average_start=load0,
                                                      load_average_end=load1, rows=rows,
                                                      wvt_final_positions=wvt_positions), indent=1))
    keys = [("truncated", "Eq. 45, truncated kernels (all)"), ("mirror", "Eq. 45, mirror ghosts (all)"),
            ("interior", "Eq. 45, interior (Eq. 44 mass of the subset)"),
            ("interior_m_phys", "Eq. 45, interior (m = pi/N)"),
            ("integral", "integral Eq. 45, r <= 1 - max H (best m)"),
            ("integral_m_phys", "integral Eq. 45, r <= 1 - max H (m = pi/N)"), ("nn_min_over_mean", "min NN / mean NN")]
    lines = [f"Command: `{command}` (load average {load0[0]:.1f} at the start, {load1[0]:.1f} at the end).", "",
             "| measure | " + " | ".join(r["set"] for r in rows) + " |", "|---" * (len(rows) + 1) + "|"]
    for key, label in keys:
        lines.append(f"| {label} | " + " | ".join(f"{r[key]:.3g}" for r in rows) + " |")
    ref = rows[0]  # ALARIC (mirror): each set's value over ALARIC's, per measure (> 1: ALARIC lower)
    for key, label in keys[:-1]:
        lines.append(f"| ratio to {ref['set']}: {label} | "
                     + " | ".join(f"{r[key] / ref[key]:.3g}" for r in rows) + " |")
    lines.append("| interior particles | " + " | ".join(str(r["interior_particles"]) for r in rows) + " |")
    lines.append("| particles within 0.1 spacing of the circle | "
                 + " | ".join(str(r["edge_particles_within_0p1_spacing"]) for r in rows) + " |")
    lines += ["", "Sets: " + "; ".join(f"{r['set']}: {r['note']}" for r in rows) + "."]
    (out / "table.md").write_text("\n".join(lines) + "\n")
    (out / "ratios.json").write_text(json.dumps(ratios(rows, [k for k, _ in keys[:-1]]), indent=1) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
