"""Closed triangle meshes (STL etc. read with trimesh) as 3D level sets.

``phi`` is the signed distance to the triangles (closest point by Ericson's
region test, Real-Time Collision Detection Sec. 5.1.5), its sign from the
generalised winding number (sum of solid angles, Van Oosterom & Strackee
1983), and ``n = grad phi = sign * (r - q) / |r - q|``, the exact gradient of
the ``phi`` returned.  The cost is O(P * triangles); for large meshes pass
``grid_spacing`` to tabulate ``phi`` on a background mesh (Fan Sec. 2) and
interpolate it with the C1 tricubic of
:class:`~ase_sphrelax.domains.table.CubicTable`.
"""
from __future__ import annotations

import math
import os

import numba
import numpy as np

from .base import Domain


@numba.njit(cache=True)
def _closest_on_triangle(p, a, b, c, q):
    """Closest point q on triangle abc to p (Ericson 5.1.5); returns dist^2."""
    ab = b - a
    ac = c - a
    ap = p - a
    d1 = ab @ ap
    d2 = ac @ ap
    if d1 <= 0.0 and d2 <= 0.0:
        q[:] = a
    else:
        bp = p - b
        d3 = ab @ bp
        d4 = ac @ bp
        vc = d1 * d4 - d3 * d2
        if d3 >= 0.0 and d4 <= d3:
            q[:] = b
        elif vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
            q[:] = a + d1 / (d1 - d3) * ab
        else:
            cp = p - c
            d5 = ab @ cp
            d6 = ac @ cp
            vb = d5 * d2 - d1 * d6
            va = d3 * d6 - d5 * d4
            if d6 >= 0.0 and d5 <= d6:
                q[:] = c
            elif vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
                q[:] = a + d2 / (d2 - d6) * ac
            elif va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
                w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
                q[:] = b + w * (c - b)
            else:
                denom = 1.0 / (va + vb + vc)
                q[:] = a + ab * (vb * denom) + ac * (vc * denom)
    e = p - q
    return e @ e


@numba.njit(cache=True)
def _mesh_phi_grad(r_pd, tri, fnormal, phi_p, g_pd):
    n_tri = tri.shape[0]
    q = np.empty(3)
    qbest = np.empty(3)
    for p in range(r_pd.shape[0]):
        x = r_pd[p].copy()
        best = np.inf
        bt = 0
        wind = 0.0
        for t in range(n_tri):
            a = tri[t, 0]
            b = tri[t, 1]
            c = tri[t, 2]
            d2 = _closest_on_triangle(x, a, b, c, q)
            if d2 < best:
                best = d2
                bt = t
                qbest[:] = q
            # solid angle of the triangle seen from x
            ra = a - x
            rb = b - x
            rc = c - x
            la = math.sqrt(ra @ ra)
            lb = math.sqrt(rb @ rb)
            lc = math.sqrt(rc @ rc)
            num = ra[0] * (rb[1] * rc[2] - rb[2] * rc[1]) \
                - ra[1] * (rb[0] * rc[2] - rb[2] * rc[0]) \
                + ra[2] * (rb[0] * rc[1] - rb[1] * rc[0])
            den = la * lb * lc + (ra @ rb) * lc + (ra @ rc) * lb + (rb @ rc) * la
            wind += 2.0 * math.atan2(num, den)
        dist = math.sqrt(best)
        if dist == 0.0:
            phi_p[p] = 0.0
            g_pd[p, :] = fnormal[bt]
            continue
        sgn = -1.0 if abs(wind) > 2.0 * math.pi else 1.0
        phi_p[p] = sgn * dist
        for d in range(3):
            g_pd[p, d] = sgn * (x[d] - qbest[d]) / dist


class Mesh(Domain):
    """3D domain enclosed by a closed (watertight) triangle mesh.

    Parameters
    ----------
    mesh : str, os.PathLike or trimesh.Trimesh
        Path of a mesh file trimesh can read (STL, OBJ, PLY, ...) or a mesh.
    grid_spacing : float, optional
        Tabulate ``phi`` on a background mesh of this spacing (C1 tricubic
        interpolation, normal = exact gradient of the interpolant).

    Raises
    ------
    ValueError
        If the mesh is not watertight (open or non-manifold) or has no volume.
    """

    dim = 3

    def __init__(self, mesh, grid_spacing=None):
        import trimesh

        if isinstance(mesh, (str, os.PathLike)):
            try:
                mesh = trimesh.load(mesh, force="mesh")
            except Exception as err:  # trimesh raises many types
                raise ValueError(f"mesh: cannot read {mesh!r}: {err}") from None
        if not isinstance(mesh, trimesh.Trimesh):
            raise TypeError(f"mesh must be a path or trimesh.Trimesh, got {type(mesh).__name__}")
        if len(mesh.faces) == 0 or not mesh.is_watertight:
            raise ValueError("mesh must be a closed (watertight) triangle mesh; "
                             f"got {len(mesh.faces)} faces, watertight={mesh.is_watertight}")
        if not mesh.is_winding_consistent:
            raise ValueError("mesh has inconsistent face winding")
        if mesh.volume < 0:
            mesh = mesh.copy()
            mesh.invert()
        if not mesh.volume > 0:
            raise ValueError("mesh encloses no volume")
        self.trimesh = mesh
        self._tri = np.ascontiguousarray(mesh.triangles, dtype=float)
        self._fn = np.ascontiguousarray(mesh.face_normals, dtype=float)
        self._volume = float(mesh.volume)
        self._table = None
        if grid_spacing is not None:
            from .table import CubicTable

            self._table = CubicTable(self._exact_phi, self.bounds, grid_spacing)

    def _exact_phi_grad(self, r_pd):
        r_pd = np.ascontiguousarray(r_pd, dtype=float)
        phi_p = np.empty(len(r_pd))
        g_pd = np.empty_like(r_pd)
        _mesh_phi_grad(r_pd, self._tri, self._fn, phi_p, g_pd)
        return phi_p, g_pd

    def _exact_phi(self, r_pd):
        return self._exact_phi_grad(r_pd)[0]

    def _phi_grad(self, r_pd):
        if self._table is not None:
            return self._table.phi_grad(r_pd)
        return self._exact_phi_grad(r_pd)

    @property
    def bounds(self):
        b = np.asarray(self.trimesh.bounds, dtype=float)
        return b[0].copy(), b[1].copy()

    @property
    def volume(self):
        """Enclosed volume (trimesh, exact for the triangulated surface)."""
        return self._volume

    def __repr__(self):
        return f"Mesh({len(self._tri)} triangles, volume={self._volume:.6g})"
