"""The PCG viscous form of BISPH (BIPI Fig. 14b) on plane Poiseuille flow: the controlled experiment.

The channel of ``tests/test_bisph.py`` (``scene.channel``: width W = 0.02 m, 10 dx long, periodic in x,
nu = 1e-3 m^2/s, F = 1 m/s^2, u_max = 0.05 m/s) at 20 and 40 particles across. On the x-invariant lattice
the viscous operator acts on layer velocities: ``op[i, j]`` is the layer-i mean of ``nu lap u`` for u = 1
on layer j. Its steady state (``u(t) = int_0^t exp(op s) F ds`` at t = 10 W^2/nu, which leaves a null mode
unexcited as the time runs do) is compared with ``scene.poiseuille``, and its slowest decay rates with
the physical ``nu pi^2 / W^2`` (24.67 1/s). Variants of step 2 of ``BISPH.laplacian`` (step 1, the
consistent gradient ``G`` with walls, is the package's):

* ``nested``: ``grad G_a = (L^p_a)^{-1} sum_b V_b (G_b - G_a) (x) grad_a W`` (particle-only matrix; the form
  before this study);
* ``nested_wall_shear`` / ``nested_wall_midpoint``: plus the wall term ``- sum_s (G_s - G_a) (x) grad gamma_as``
  (full matrix) with ``G_s = (v_a/delta) n`` (the wall shear as the wall's value of G) or
  ``(2 v_a/delta - G_a n) n`` (the value at the wall of a parabola through v_a with slope G_a);
* ``midpoint_only``: ``G_b`` replaced by the pair's midpoint gradient ``G_ab`` (``BISPH.laplacian``), no
  wall term, factor 2, particle-only matrix;
* ``midpoint_wall_half`` / ``pcg``: plus the wall's midpoint gradient ``G_as`` at half / full weight
  (``pcg`` is the package's ``BISPH.laplacian``; this script checks it against its own sum);
* ``boundary_layer``: the package's default form (Morris' sum and the wall shear).

Then the package's time runs (``BISPH.run``) at 20 across, both forms, the maximum of |u - u_exact| / u_max at
0.6 and 1.2 W^2/nu. Writes ``summary.json``. About a minute on one core.

    python reproductions/bipi-pcg-poiseuille/run.py --out reproductions/bipi-pcg-poiseuille/results
"""
import argparse
import json
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from ase_sphrelax.flows.bisph import SHEAR_FLOOR
from ase_sphrelax.flows.scene import channel, poiseuille

WIDTH, FORCE, MU = 0.02, 1.0, 1.0
VARIANTS = ("nested", "nested_wall_shear", "nested_wall_midpoint", "midpoint_only", "midpoint_wall_half", "pcg")


def step2(sim, bt, gamma, v, variant):
    """``lap v`` (N, 2) with step 2 of the named variant (numpy, the pairs from a k-d tree)."""
    G = sim._consistent(bt, gamma, v)[0]  # [a, c, i] = d_i v_c, walls included
    x, length = sim.r[:, :2], sim.cell[0, 0]
    a, b = cKDTree(x, boxsize=[length, 1e3]).query_pairs(sim.h, output_type="ndarray").T
    d = x[b] - x[a]
    d[:, 0] -= length * np.round(d[:, 0] / length)
    r = np.linalg.norm(d, axis=1)
    ga = -(sim.kernel.dw(r, sim.h) / r)[:, None] * d  # grad_a W; grad_b W = -grad_a W
    vol = sim.mass / sim.rho
    n = len(v)
    if variant.startswith("nested"):
        g_a, g_b, factor = G[b], G[a], 1.0  # a sees G_b, b sees G_a
    else:
        mid = 0.5 * (G[a] + G[b])
        e = d / r[:, None]
        mid = mid + ((v[b] - v[a]) / r[:, None] - np.einsum("pcj,pj->pc", mid, e))[:, :, None] * e[:, None, :]
        g_a, g_b, factor = mid, mid, 2.0
    nsum, lmat = np.zeros((n, 2, 2, 2)), np.zeros((n, 2, 2))
    np.add.at(nsum, a, vol[b][:, None, None, None] * (g_a - G[a])[..., None] * ga[:, None, None, :])
    np.add.at(nsum, b, -vol[a][:, None, None, None] * (g_b - G[b])[..., None] * ga[:, None, None, :])
    np.add.at(lmat, a, vol[b][:, None, None] * ga[:, :, None] * d[:, None, :])
    np.add.at(lmat, b, vol[a][:, None, None] * ga[:, :, None] * d[:, None, :])
    if variant not in ("nested", "midpoint_only"):
        pairs = bt.pairs
        owner = np.repeat(np.arange(n), np.diff(pairs.start_p))
        normal = sim._seg[pairs.element_k, 4:6]
        off = sim._feet(bt) - pairs.x_sc[pairs.point_k, :2]  # y_as - x_a
        delta = np.maximum(pairs.distance_k, SHEAR_FLOOR * sim.dx)[:, None]
        g_own, v_own = G[owner], v[owner]
        if variant == "nested_wall_shear":
            gs = (v_own / delta)[:, :, None] * normal[:, None, :]
        elif variant == "nested_wall_midpoint":
            gs = (2.0 * v_own / delta - np.einsum("kci,ki->kc", g_own, normal))[:, :, None] * normal[:, None, :]
        else:
            jump = (v_own + np.einsum("kci,ki->kc", g_own, off)) / delta
            gs = g_own + jump[:, :, None] * normal[:, None, :]
        weight = 0.5 if variant == "midpoint_wall_half" else 1.0
        grad_gamma = bt.grad_k[:, None] * normal
        np.add.at(nsum, owner, -weight * (gs - g_own)[..., None] * grad_gamma[:, None, None, :])
        np.add.at(lmat, owner, -grad_gamma[:, :, None] * off[:, None, :])
    grad_g = factor * np.einsum("ajk,acik->acij", np.linalg.inv(lmat), nsum)
    return grad_g[:, :, 0, 0] + grad_g[:, :, 1, 1]


def layer_operator(n, variant):
    dx = WIDTH / n
    sim = channel(WIDTH, 10 * dx, dx, force=FORCE, mu=MU, viscosity="pcg")
    layer = np.round(sim.r[:, 1] / dx - 0.5).astype(int)
    bt, gamma = sim.walls()
    count = np.bincount(layer, minlength=n)
    op = np.zeros((n, n))
    for j in range(n):
        v = np.zeros((len(sim.r), 2))
        v[layer == j, 0] = 1.0
        if variant == "boundary_layer":
            sim.v[:, :2] = v
            sim.viscosity = "boundary_layer"
            lap = sim._momentum(bt, gamma, np.zeros(len(sim.r)))[0][:, 0] - FORCE  # p = 0 at rho0
        else:
            lap = MU / sim.rho0 * step2(sim, bt, gamma, v, variant)[:, 0]
            if variant == "pcg":
                package = MU / sim.rho0 * sim.laplacian(v, bt, gamma)[:, 0]
                assert np.allclose(lap, package, rtol=1e-9, atol=1e-9 * np.abs(package).max())
        op[:, j] = np.bincount(layer, weights=lap, minlength=n) / count
    return op


def steady(op, n, t_nu=10.0):
    rate, vec = np.linalg.eig(op)
    coef = np.linalg.solve(vec, FORCE * np.ones(n))
    t = t_nu * WIDTH**2 * 1000.0 / MU
    small = np.abs(rate) < 1e-9
    growth = np.where(small, t, (np.exp(rate * t) - 1.0) / np.where(small, 1.0, rate))
    u = (vec @ (coef * growth)).real
    exact = poiseuille(WIDTH / n * (np.arange(n) + 0.5), WIDTH, FORCE, MU)
    return float(np.abs(u - exact).max() / exact.max()), sorted(float(-x) for x in rate.real)[:2]


def time_run(viscosity, n=20, times=(0.6, 1.2)):
    dx = WIDTH / n
    sim = channel(WIDTH, 10 * dx, dx, force=FORCE, mu=MU, viscosity=viscosity)
    out = {}
    for t_nu in times:
        sim.run(t_nu * WIDTH**2 * sim.rho0 / MU, progress=False)
        exact = poiseuille(sim.r[:, 1], WIDTH, FORCE, MU)
        out[str(t_nu)] = float(np.abs(sim.v[:, 0] - exact).max() / exact.max())
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--sizes", type=int, nargs="+", default=[20, 40])
    args = parser.parse_args()
    summary = {"physical_rate": MU / 1000.0 * np.pi**2 / WIDTH**2, "steady": {}, "time_runs": {}}
    for n in args.sizes:
        rows = {}
        for variant in VARIANTS + ("boundary_layer",):
            err, rates = steady(layer_operator(n, variant), n)
            rows[variant] = {"max_error": err, "slowest_rates": rates}
            print(f"n={n} {variant}: steady max |u - u_exact|/u_max = {err:.2e}, slowest rates {rates}", flush=True)
        summary["steady"][f"n{n}"] = rows
    for viscosity in ("pcg", "boundary_layer"):
        summary["time_runs"][viscosity] = time_run(viscosity)
        print(viscosity, summary["time_runs"][viscosity], flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "summary.json").write_text(json.dumps(summary, indent=1) + "\n")


if __name__ == "__main__":
    main()
