"""Fan's relaxation at corners: five boundary terms on a box, a chevron (sharp tips, a concave corner), a cube.

Issue 33 item 3. Routes (all with exact forces -dE/dx, Eq. 2.4 steps, c = 0.01, KeepInDomain):

* ``level_set``: Fan's Eq. 3.8/4.4 term ``2 vt I(-phi)`` on the exact distance (the old default).
* ``gamma_continuum``: route (a), the wall as a continuum, ``2 vt (1 - gamma)`` with BIPI's exact
  ``gamma`` of the boundary elements, without the contact core (``FanModel.core_stiffness = 0``).
* ``gamma_k11``: the same continuum 10 % stiffer (``wall_weight = 1.1``), no core.
* ``gamma``: route (a) as the package's default: the continuum plus the contact core
  ``B max(d0 + phi, 0)^2 / (2 d0 h)``, ``d0 = 0.4 dx``, ``B = 2`` (``ase_sphrelax.models.fan``); on the chevron (a
  Polygon) the wall is its opening at 0.35 dx (``FanModel.wall``; the ``gamma_*`` routes too), the box and cube
  keep their own (``reproductions/fan-thin-features``).
* ``per_wall``: route (b), a corner-aware level-set term: Fan's ``I`` summed over the walls,
  each with the distance to its own segment (2D) or face (3D), so no gradient jumps at corners.
* ``smoothed``: route (c), Fan's ``I`` of a smoothed distance, the soft minimum
  ``-eps log sum_w exp(-d_w / eps)`` of the walls' distances (``eps = dx / 4``).

Metrics after the run (``--out``/corners.json): the smallest distance of a particle to the
boundary in dx, particles outside, the completed kernel-sum error
``|sum_j V W_ij + (1 - gamma_i) - 1|`` (exact gamma) near walls (``phi > -h``) and inside, the
interior kernel-gradient error ``h |sum_j V grad W_ij|`` and near walls its completed form
``h |sum_j V grad W_ij - grad gamma_i|``.

    python reproductions/fan-corners/run.py --out reproductions/fan-corners/results
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from ase_sphrelax import FanCalculator
from ase_sphrelax.analysis.quality import Quality
from ase_sphrelax.boundary import BoundarySegments, gamma_and_gradient
from ase_sphrelax.build import fill
from ase_sphrelax.domains import Box, Polygon
from ase_sphrelax.drivers.fan_relaxation import FanRelaxation
from ase_sphrelax.models.fan import FanModel

ROUTES = ("level_set", "gamma_continuum", "gamma_k11", "gamma", "per_wall", "smoothed")
L = 0.375


def shapes(n2, n3):
    chevron = Polygon([[(0.0, 0.0), (0.5, 0.25), (0.0, 0.5), (0.175, 0.25)]])  # 28 and 53 degree tips, a concave corner
    return {
        "box": (Box((0.0, 0.0), (L, L)), L / n2),
        "chevron": (chevron, float(np.sqrt(chevron.volume / (0.8 * n2 * n2)))),
        "cube": (Box((0.0, 0.0, 0.0), (L, L, L)), L / n3),
    }


def wall_distances(domain, r_pc):
    """Distances (P, W) of the points to each wall and their gradients (P, W, 3).

    Walls: the merged segments in 2D, the box's six faces in 3D."""
    p = len(r_pc)
    if domain.dim == 2:
        seg = BoundarySegments.from_domain(domain).merged()
        a_wc, b_wc = np.asarray(seg.start_sc, float), np.asarray(seg.end_sc, float)
        x = r_pc[:, None, :2]
        ab = b_wc - a_wc
        t = np.clip(np.einsum("pwc,wc->pw", x - a_wc, ab) / np.einsum("wc,wc->w", ab, ab), 0.0, 1.0)
        foot = a_wc + t[..., None] * ab
        diff = x - foot
    else:
        lo, hi = np.asarray(domain.lo, float), np.asarray(domain.hi, float)
        diff = np.zeros((p, 6, 3))
        for w in range(6):
            axis, side = divmod(w, 2)
            plane = lo[axis] if side == 0 else hi[axis]
            foot = np.clip(r_pc[:, :3], lo, hi)
            foot[:, axis] = plane
            diff[:, w] = r_pc[:, :3] - foot
        return _norm_and_gradient(diff)
    out = np.zeros((p, diff.shape[1], 3))
    out[..., :2] = diff
    return _norm_and_gradient(out)


def _norm_and_gradient(diff):
    d = np.linalg.norm(diff, axis=-1)
    return d, diff / np.maximum(d, 1e-300)[..., None]


class WallModel(FanModel):
    """Routes (b) and (c): Fan's ``I`` of per-wall or soft-min distances (particles kept inside)."""

    route = "per_wall"
    eps = None

    def boundary(self, r_pc, v0, want_forces=True, nlist=None, out=None, candidates=None, phi_out=None):
        """The route's term and force on every particle; with ``out`` (the calculator's arrays, the energies None
        for forces alone) added to them in place, and ``phi_out`` given the level set of the ``candidates``, as
        :meth:`FanModel.boundary`."""
        if phi_out is not None:
            phi_out[:] = self._phi(np.asarray(r_pc, float)[candidates])
        d_pw, g_pwc = wall_distances(self.domain, np.asarray(r_pc, float))
        k = self.kernel
        if self.route == "per_wall":
            e_p = 2.0 * v0 * k.w1_tail_integral(d_pw, self.h).sum(axis=1)
            f_pc = 2.0 * v0 * np.einsum("pw,pwc->pc", k.w1(np.minimum(d_pw, self.h), self.h), g_pwc)
        else:
            m_p = d_pw.min(axis=1)
            w_pw = np.exp(-(d_pw - m_p[:, None]) / self.eps)
            s_p = m_p - self.eps * np.log(w_pw.sum(axis=1))
            grad_pc = np.einsum("pw,pwc->pc", w_pw / w_pw.sum(axis=1)[:, None], g_pwc)
            e_p = 2.0 * v0 * k.w1_tail_integral(s_p, self.h)
            f_pc = 2.0 * v0 * k.w1(np.clip(s_p, 0.0, self.h), self.h)[:, None] * grad_pc
        if out is not None:
            e_out, f_out = out
            if e_out is not None:
                e_out += e_p
            if want_forces:
                f_out += f_pc
            return e_out, (f_out if want_forces else None)
        return e_p, (f_pc if want_forces else None)


def calculator(route, domain, dx, h):
    if route in ("level_set", "gamma"):
        return FanCalculator(h=h, dx=dx, domain=domain, dim=domain.dim, boundary_term=route)
    calc = FanCalculator(h=h, dx=dx, domain=domain, dim=domain.dim, boundary_term="gamma")
    if route.startswith("gamma_"):
        calc.model.core_stiffness = 0.0
        calc.model.wall_weight = 1.1 if route == "gamma_k11" else 1.0
        return calc
    model = WallModel(h, dx, domain, domain.dim, "wendland_c2", "level_set")
    model.route, model.eps = route, 0.25 * dx
    calc.model = model
    return calc


def metrics(atoms, domain, dx, h):
    q = Quality(h, dx, domain, domain.dim).compute(atoms)
    gamma_p, grad_pc = gamma_and_gradient(atoms.positions, domain, h)
    completed_p = q.kernel_sum_p + (1.0 - gamma_p)
    near = q.phi_p > -h
    from ase_sphrelax.kernel_sums import kernel_sums
    from ase_sphrelax.neighbors import NeighborList

    nl = NeighborList(h)
    nl.update(atoms.positions, atoms.cell.array, atoms.pbc)
    sums = kernel_sums(nl, np.array(atoms.positions), h, q.kernel)
    completed_grad_p = h * np.linalg.norm(q.v0 * sums.grad_pc - grad_pc, axis=1)
    d_p = -q.phi_p / dx

    def top(x):
        return float(x.max()) if len(x) else None

    return dict(
        n_particles=len(atoms),
        boundary_distance_min=float(d_p.min()),
        n_below_035=int((d_p < 0.35).sum()),
        n_outside=int((q.phi_p > 0).sum()),
        completed_error_max_near_wall=float(np.abs(completed_p[near] - 1).max()),
        completed_error_max_interior=top(np.abs(completed_p[~near] - 1)),
        completed_std_near_wall=float(np.std(completed_p[near])),
        completed_gradient_max_near_wall=float(completed_grad_p[near].max()),
        gradient_error_max_interior=top(q.gradient_error_p[q.interior_p]),
        gradient_error_mean_interior=float(q.gradient_error_p[q.interior_p].mean()) if q.interior_p.any() else None,
    )


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--n2", type=int, default=24, help="2D box: particles per side")
    parser.add_argument("--n3", type=int, default=8, help="3D cube: particles per side")
    parser.add_argument("--steps", type=int, default=1000, help="Eq. 2.4 steps in 2D (3D: half)")
    parser.add_argument("--routes", nargs="+", default=list(ROUTES), choices=ROUTES)
    parser.add_argument("--shapes", nargs="+", default=["box", "chevron", "cube"])
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    out = dict(command="python reproductions/fan-corners/run.py --out reproductions/fan-corners/results",
               h_over_dx=2.6, c=0.01, jitter=0.1, seed=0, shapes={})
    for name, (domain, dx) in shapes(args.n2, args.n3).items():
        if name not in args.shapes:
            continue
        h = 2.6 * dx
        steps = args.steps if domain.dim == 2 else args.steps // 2
        origin = domain.bounds[0] if isinstance(domain, Box) else None
        start = fill(domain, dx, jitter=0.1, seed=0, origin=origin)
        row = dict(dx=dx, steps=steps, start=metrics(start, domain, dx, h), routes={})
        for route in args.routes:
            atoms = start.copy()
            atoms.calc = calculator(route, domain, dx, h)
            t0 = time.perf_counter()
            FanRelaxation(atoms, c=0.01, logfile=None).run(fmax=0.0, steps=steps)
            atoms.set_constraint()
            m = metrics(atoms, domain, dx, h)
            m["wall_time_s"] = round(time.perf_counter() - t0, 2)
            row["routes"][route] = m
            print(name, route, {k: (round(v, 4) if isinstance(v, float) else v) for k, v in m.items()}, flush=True)
        out["shapes"][name] = row
    (args.out / "corners.json").write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
