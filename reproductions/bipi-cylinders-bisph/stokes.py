"""The cylinder cell's Reynolds number by a second, independent method: steady Stokes flow on a grid.

BISPH's steady state in this cell (``run.py``) gives the paper's Re = rho0 v_bar r_cyl / mu as 0.87 with the
paper's F = 100 m/s^2, mu = 10 Pa s, rho0 = 1000 kg/m^3 and BIPI2D's own geometry file; the paper states 9.8.
Before blaming either, this script computes v_bar with no SPH at all:

* steady Stokes equations ``mu lap(u) - grad p + rho0 F e_x = 0``, ``div u = 0`` (the inertia BISPH keeps is
  left out: at Re ~ 1 it changes v_bar by a few per cent at most, while the gap to 9.8 is a factor of 11);
* a staggered (MAC) grid of square cells, periodic in x, no slip on the plates (ghost values) and on the
  cylinder (cells whose centre lies inside it are solid; the faces touching them carry u = 0: a staircase,
  first order in the cell size), solved directly (``scipy.sparse.linalg.spsolve``), the pressure fixed in one cell;
* v_bar as ``run.py`` takes it: the mean of u over the fluid within h (the kernel support, 0.016 m) of the
  periodic faces;
* three grids, the last two extrapolated (Richardson, first order), and the same solver on the cell without the
  cylinder, against plane Poiseuille flow's v_bar = rho0 F H^2 / (12 mu) (its check).

    python reproductions/bipi-cylinders-bisph/stokes.py --out reproductions/bipi-cylinders-bisph/results
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import spsolve

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from lib.results_io import write_json  # noqa: E402

RHO0, MU, FORCE, R_CYL = 1000.0, 10.0, 100.0, 0.02  # the paper's (as run.py)
LX, LY, CENTRE = 0.12, 0.08, (0.06, 0.04)  # BIPI2D's PeriodicCylinderArray cell (PeriodicCylinderArray.edges)
BAND = 0.016  # run.py's h (4 dx at dx = 0.004): the band beside the periodic faces that v_bar averages


def stokes_cell(n_y, cylinder=True):
    """Steady Stokes flow in the cell on ``(1.5 n_y) x n_y`` square cells.

    Returns
    -------
    dict
        ``v_bar`` (mean u within BAND of the periodic faces), ``v_mean`` (flux / LY), ``u_max``, ``cells``.
    """
    d = LY / n_y
    n_x = int(round(LX / d))
    xc = (np.arange(n_x) + 0.5) * d
    yc = (np.arange(n_y) + 0.5) * d
    solid_ij = np.zeros((n_x, n_y), bool)
    if cylinder:
        solid_ij = (xc[:, None] - CENTRE[0]) ** 2 + (yc[None, :] - CENTRE[1]) ** 2 < R_CYL ** 2
    n_u, n_v = n_x * n_y, n_x * (n_y - 1)  # u on faces x = i d; v on the interior faces y = j d, j = 1..n_y-1
    iu = lambda i, j: (i % n_x) * n_y + j  # noqa: E731
    iv = lambda i, j: n_u + (i % n_x) * (n_y - 1) + (j - 1)  # noqa: E731
    ip = lambda i, j: n_u + n_v + (i % n_x) * n_y + j  # noqa: E731
    rows, cols, vals = [], [], []
    rhs = np.zeros(n_u + n_v + n_x * n_y)

    def put(r, c, v):
        rows.append(r), cols.append(c), vals.append(v)

    c_lap = MU / d ** 2
    for i in range(n_x):
        for j in range(n_y):
            # u face between cells (i-1, j) and (i, j)
            r = iu(i, j)
            if solid_ij[i, j] or solid_ij[(i - 1) % n_x, j]:
                put(r, r, 1.0)
            else:
                diag = -4.0
                for di in (-1, 1):
                    ii = i + di
                    if not (solid_ij[ii % n_x, j] or solid_ij[(ii - 1) % n_x, j]):
                        put(r, iu(ii, j), c_lap)
                for dj in (-1, 1):
                    jj = j + dj
                    if jj < 0 or jj >= n_y:
                        diag -= 1.0  # ghost value -u: the plate lies half a cell away
                    elif not (solid_ij[i, jj] or solid_ij[(i - 1) % n_x, jj]):
                        put(r, iu(i, jj), c_lap)
                put(r, r, diag * c_lap)
                put(r, ip(i, j), -1.0 / d)
                put(r, ip(i - 1, j), 1.0 / d)
                rhs[r] = -RHO0 * FORCE
            # v face between cells (i, j-1) and (i, j)
            if j >= 1:
                r = iv(i, j)
                if solid_ij[i, j] or solid_ij[i, j - 1]:
                    put(r, r, 1.0)
                else:
                    put(r, r, -4.0 * c_lap)
                    for di in (-1, 1):
                        ii = (i + di) % n_x
                        if not (solid_ij[ii, j] or solid_ij[ii, j - 1]):
                            put(r, iv(ii, j), c_lap)
                    for jj in (j - 1, j + 1):
                        if 1 <= jj <= n_y - 1 and not (solid_ij[i, jj] or solid_ij[i, jj - 1]):
                            put(r, iv(i, jj), c_lap)  # v = 0 on the plates (j = 0, n_y)
                    put(r, ip(i, j), -1.0 / d)
                    put(r, ip(i, j - 1), 1.0 / d)
    pinned = False
    for i in range(n_x):
        for j in range(n_y):
            r = ip(i, j)
            if solid_ij[i, j] or not pinned:
                put(r, r, 1.0)  # no pressure in solid cells; one fluid cell fixes the constant
                pinned = pinned or not solid_ij[i, j]
                continue
            put(r, iu(i + 1, j), 1.0 / d)
            put(r, iu(i, j), -1.0 / d)
            if j + 1 <= n_y - 1:
                put(r, iv(i, j + 1), 1.0 / d)
            if j >= 1:
                put(r, iv(i, j), -1.0 / d)
    a = sp.csr_matrix((vals, (rows, cols)), shape=(rhs.size, rhs.size))
    sol = spsolve(a.tocsc(), rhs)
    u_ij = sol[:n_u].reshape(n_x, n_y)
    x_face = np.arange(n_x) * d
    band = (x_face < BAND) | (x_face > LX - BAND)
    fluid = ~(solid_ij | np.roll(solid_ij, 1, axis=0))
    return {"cells": [n_x, n_y], "cell_size": d, "v_bar": float(u_ij[band][fluid[band]].mean()),
            "v_mean": float(u_ij[0].sum() * d / LY), "u_max": float(u_ij.max())}


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", default=str(Path(__file__).resolve().parent / "results"))
    parser.add_argument("--grids", default="40,80,160", help="cells across the gap (each next one twice the last)")
    args = parser.parse_args()
    grids = [int(g) for g in args.grids.split(",")]
    poiseuille = {"analytic_v_bar": RHO0 * FORCE * LY ** 2 / (12 * MU)}
    poiseuille.update(stokes_cell(grids[-1], cylinder=False))
    poiseuille["relative_error"] = poiseuille["v_bar"] / poiseuille["analytic_v_bar"] - 1
    print(f"check, no cylinder: v_bar {poiseuille['v_bar']:.4f} m/s, plane Poiseuille "
          f"{poiseuille['analytic_v_bar']:.4f} ({100 * poiseuille['relative_error']:+.3f} %)")
    rows = []
    for n_y in grids:
        row = stokes_cell(n_y)
        row["reynolds"] = RHO0 * row["v_bar"] * R_CYL / MU
        rows.append(row)
        print(f"{row['cells'][0]} x {row['cells'][1]} cells: v_bar {row['v_bar']:.4f} m/s, Re {row['reynolds']:.3f}")
    v_rich = 2 * rows[-1]["v_bar"] - rows[-2]["v_bar"]  # first order: the staircase cylinder
    out = {"method": "steady Stokes, MAC grid, staircase cylinder, direct sparse solve; no SPH",
           "rho0": RHO0, "mu": MU, "force": FORCE, "r_cyl": R_CYL, "cell": [LX, LY], "band": BAND,
           "poiseuille_check": poiseuille, "grids": rows,
           "v_bar_extrapolated": v_rich, "reynolds_extrapolated": RHO0 * v_rich * R_CYL / MU,
           "reynolds_paper": 9.8, "v_bar_for_paper_reynolds": 9.8 * MU / (RHO0 * R_CYL),
           "paper_v_bar_over_poiseuille": 9.8 * MU / (RHO0 * R_CYL) / poiseuille["analytic_v_bar"],
           "command": "python reproductions/bipi-cylinders-bisph/stokes.py " + " ".join(sys.argv[1:])}
    print(f"Richardson: v_bar {v_rich:.4f} m/s, Re {out['reynolds_extrapolated']:.3f} (paper 9.8 needs "
          f"v_bar {out['v_bar_for_paper_reynolds']:.2f} m/s)")
    Path(args.out).mkdir(parents=True, exist_ok=True)
    write_json(Path(args.out) / "stokes.json", out)


if __name__ == "__main__":
    main()
