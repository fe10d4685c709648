"""Closed triangle meshes (STL etc. read with trimesh) as 3D level sets.

``phi`` is the signed distance to the triangles.  The closest point ``q`` is
found by Ericson's region test (Real-Time Collision Detection Sec. 5.1.5)
among the candidates of a uniform bucket grid (the candidate list of a cell
provably contains the nearest triangle of every point in it; points outside
the grid test all triangles).  The sign comes from the angle-weighted
pseudo-normal of the closest feature (face, edge or vertex; Baerentzen &
Aanaes, IEEE TVCG 11, 243 (2005)), and ``n = grad phi = sign (r - q)/|r - q|``
is the exact gradient of the ``phi`` returned (one-sided on the medial axis).

Pass ``grid_spacing`` to tabulate ``phi`` on a background mesh (Fan Sec. 2)
and interpolate it with the C1 tricubic of
:class:`~ase_sphrelax.domains.table.CubicTable`.
"""
from __future__ import annotations

import math
import os

import numba
import numpy as np

from ..checks import check_positive
from .base import SearchedDomain
from .closest import closest_on_triangle


@numba.njit(cache=True)
def _bucket_count(tri, glo, gh, gn, out_start, out_list, fill):
    """Candidate triangles per bucket cell (count pass, then fill pass).

    Nearest triangle s* of any point in a cell (centre c, diagonal 2 rho)
    satisfies dist(c, s*) <= min_s dist(c, s) + 2 rho.
    """
    n_tri = tri.shape[0]
    diag = gh * math.sqrt(3.0)
    d2 = np.empty(n_tri)
    for ix in range(gn[0]):
        for iy in range(gn[1]):
            for iz in range(gn[2]):
                cx = glo[0] + (ix + 0.5) * gh
                cy = glo[1] + (iy + 0.5) * gh
                cz = glo[2] + (iz + 0.5) * gh
                best = np.inf
                for s in range(n_tri):
                    d = closest_on_triangle(cx, cy, cz, tri[s])[0]
                    d2[s] = d
                    if d < best:
                        best = d
                lim = math.sqrt(best) + diag
                lim2 = lim * lim * (1.0 + 1e-12) + 1e-300
                cell = (ix * gn[1] + iy) * gn[2] + iz
                k = 0
                for s in range(n_tri):
                    if d2[s] <= lim2:
                        if fill:
                            out_list[out_start[cell] + k] = s
                        k += 1
                if not fill:
                    out_start[cell + 1] = k


@numba.njit(cache=True)
def _mesh_phi_grad(r_pd, tri, pn, glo, gh, gn, start, cand, phi_p, g_pd):
    n_tri = tri.shape[0]
    for p in range(r_pd.shape[0]):
        px = r_pd[p, 0]
        py = r_pd[p, 1]
        pz = r_pd[p, 2]
        if not (math.isfinite(px) and math.isfinite(py) and math.isfinite(pz)):
            phi_p[p] = np.nan
            g_pd[p, :] = np.nan
            continue
        ix = int(math.floor((px - glo[0]) / gh))
        iy = int(math.floor((py - glo[1]) / gh))
        iz = int(math.floor((pz - glo[2]) / gh))
        inside_grid = 0 <= ix < gn[0] and 0 <= iy < gn[1] and 0 <= iz < gn[2]
        if inside_grid:
            cell = (ix * gn[1] + iy) * gn[2] + iz
            k0 = start[cell]
            k1 = start[cell + 1]
        else:
            k0 = 0
            k1 = n_tri
        best = np.inf
        bs = 0
        bf = 6
        qx = qy = qz = 0.0
        for k in range(k0, k1):
            s = cand[k] if inside_grid else k
            d, x, y, z, f = closest_on_triangle(px, py, pz, tri[s])
            if d < best:
                best = d
                bs = s
                bf = f
                qx, qy, qz = x, y, z
        ex = px - qx
        ey = py - qy
        ez = pz - qz
        dist = math.sqrt(best)
        side = ex * pn[bs, bf, 0] + ey * pn[bs, bf, 1] + ez * pn[bs, bf, 2]
        if dist == 0.0 or side == 0.0:
            phi_p[p] = dist
            g_pd[p, 0] = pn[bs, 6, 0]
            g_pd[p, 1] = pn[bs, 6, 1]
            g_pd[p, 2] = pn[bs, 6, 2]
            continue
        sgn = 1.0 if side > 0.0 else -1.0
        phi_p[p] = sgn * dist
        g_pd[p, 0] = sgn * ex / dist
        g_pd[p, 1] = sgn * ey / dist
        g_pd[p, 2] = sgn * ez / dist


def pseudo_normals(mesh):
    """Per face, the pseudo-normals of its 7 features (a, b, c, ab, ac, bc, face)."""
    faces = np.asarray(mesh.faces)
    fn = np.asarray(mesh.face_normals, dtype=float)
    tri = np.asarray(mesh.triangles, dtype=float)
    # angle-weighted vertex normals
    vn = np.zeros((len(mesh.vertices), 3))
    for k in range(3):
        e1 = tri[:, (k + 1) % 3] - tri[:, k]
        e2 = tri[:, (k + 2) % 3] - tri[:, k]
        cosang = np.einsum("fd,fd->f", e1, e2) / (
            np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1))
        ang = np.arccos(np.clip(cosang, -1.0, 1.0))
        np.add.at(vn, faces[:, k], ang[:, None] * fn)
    # edge normals: sum of the two adjacent face normals
    pairs = [(0, 1), (0, 2), (1, 2)]
    e_fk = np.stack([np.sort(faces[:, list(pr)], axis=1) for pr in pairs], axis=1)
    uniq, inv = np.unique(e_fk.reshape(-1, 2), axis=0, return_inverse=True)
    en = np.zeros((len(uniq), 3))
    np.add.at(en, inv.ravel(), np.repeat(fn, 3, axis=0))
    pn = np.empty((len(faces), 7, 3))
    pn[:, 0:3] = vn[faces]
    pn[:, 3:6] = en[inv.reshape(-1, 3)]
    pn[:, 6] = fn
    return np.ascontiguousarray(pn)


def _winding_numbers(points_pc, triangles_tkc, chunk=2_000_000):
    """Generalised winding number of a closed triangle surface at ``points_pc`` (Van Oosterom & Strackee's
    solid angle, IEEE Trans. Biomed. Eng. 30, 125 (1983)): 1 inside an outward-wound body, 0 outside."""
    out_p = np.zeros(len(points_pc))
    step = max(1, chunk // max(len(triangles_tkc), 1))
    for s in range(0, len(points_pc), step):
        a, b, c = (triangles_tkc[None, :, k, :] - points_pc[s:s + step, None, :] for k in range(3))
        la, lb, lc = (np.linalg.norm(v, axis=2) for v in (a, b, c))
        num = np.einsum("ptc,ptc->pt", a, np.cross(b, c))
        den = (la * lb * lc + np.einsum("ptc,ptc->pt", a, b) * lc + np.einsum("ptc,ptc->pt", a, c) * lb
               + np.einsum("ptc,ptc->pt", b, c) * la)
        out_p[s:s + step] = 2.0 * np.arctan2(num, den).sum(axis=1) / (4.0 * np.pi)
    return out_p


def check_volume(mesh, name="mesh"):
    """Return ``mesh`` (outward wound) if it bounds a volume; a one-line ValueError otherwise.

    trimesh's checks: faces present, ``is_watertight``, ``is_winding_consistent``, positive
    ``volume``. Then the bodies (connected parts, ``mesh.split``) must not overlap: every vertex of a
    body must lie outside the other bodies (winding number 0), or inside exactly one when the body
    is a cavity (wound inwards). Overlapping or doubly nested bodies count a region twice, and both
    the signed distance and the boundary integrals are then wrong. (A body that intersects itself
    is not detected.)
    """
    n_faces = len(mesh.faces)
    if n_faces == 0:
        raise ValueError(f"{name}: no triangles (not a mesh file trimesh can read, or an empty mesh)")
    if not mesh.is_watertight:
        raise ValueError(f"{name} must be a closed (watertight) triangle mesh; it has holes or non-manifold "
                         f"edges ({n_faces} faces; trimesh's is_watertight is False)")
    if not mesh.is_winding_consistent:
        raise ValueError(f"{name} has inconsistent face winding (trimesh's is_winding_consistent is False): "
                         "fix the normals (e.g. trimesh.repair.fix_normals)")
    if mesh.volume < 0:
        mesh = mesh.copy()
        mesh.invert()
    if not mesh.volume > 0:
        raise ValueError(f"{name} encloses no volume")
    bodies = mesh.split(only_watertight=False) if mesh.body_count > 1 else []
    for i, body in enumerate(bodies):
        lo, hi = body.bounds
        expected = 0.0 if body.volume > 0 else 1.0
        pts_pc = np.asarray(body.vertices, dtype=float)
        w_p = np.zeros(len(pts_pc))
        for j, other in enumerate(bodies):
            if j == i:
                continue
            olo, ohi = other.bounds
            near = np.all((pts_pc >= olo) & (pts_pc <= ohi), axis=1)
            if near.any():
                w_p[near] += _winding_numbers(pts_pc[near], np.asarray(other.triangles, dtype=float))
        bad = np.abs(w_p - expected) > 0.25
        if bad.any():
            raise ValueError(f"{name} is self-intersecting: {int(bad.sum())} vertices of body {i} (of "
                             f"{len(bodies)}) lie inside another body; a mesh must bound one volume without "
                             "overlapping parts (merge them, e.g. with a boolean union)")
    return mesh


class Mesh(SearchedDomain):
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
        If the mesh does not bound a volume (:func:`check_volume`): not watertight (open or
        non-manifold), inconsistently wound, enclosing no volume, or made of overlapping bodies.
    """

    dim = 3

    def __init__(self, mesh, grid_spacing=None):
        import trimesh

        name = "mesh"
        if isinstance(mesh, (str, os.PathLike)):
            name = f"mesh {os.fspath(mesh)!r}"
            try:
                mesh = trimesh.load(mesh, force="mesh")
            except Exception as err:  # trimesh raises many types
                raise ValueError(f"mesh: cannot read {mesh!r}: {err}") from None
        if not isinstance(mesh, trimesh.Trimesh):
            raise TypeError(f"mesh must be a path or trimesh.Trimesh, got {type(mesh).__name__}")
        mesh = check_volume(mesh, name)
        self.trimesh = mesh
        self._tri = np.ascontiguousarray(np.asarray(mesh.triangles, dtype=float).reshape(-1, 9))
        self._pn = pseudo_normals(mesh)
        self._volume = float(mesh.volume)
        self._build_buckets()
        self._table = None
        if grid_spacing is not None:
            from .table import CubicTable

            grid_spacing = check_positive("grid_spacing", grid_spacing)
            self._table = CubicTable(self._exact_phi, self.bounds, grid_spacing)

    def _build_buckets(self):
        lo, hi = self.bounds
        ext = hi - lo
        n_tri = len(self._tri)
        # about 2 triangles per cell; build cost cells * triangles capped at 4e8
        n_cells = int(min(max(2 * n_tri, 64), 64**3, 4e8 / n_tri))
        gh = float((np.prod(ext + 1e-12 * ext.max()) / n_cells) ** (1.0 / 3.0))
        gh = max(gh, 1e-3 * float(ext.max()))
        self._glo = lo - gh
        self._gh = gh
        self._gn = np.ceil((ext + 2 * gh) / gh).astype(np.int64) + 1
        n_cell = int(np.prod(self._gn))
        start = np.zeros(n_cell + 1, np.int64)
        _bucket_count(self._tri, self._glo, gh, self._gn, start, np.empty(0, np.int64), False)
        start = np.cumsum(start)
        cand = np.empty(start[-1], np.int64)
        _bucket_count(self._tri, self._glo, gh, self._gn, start, cand, True)
        self._start, self._cand = start, cand

    def _exact_phi_grad(self, r_pd):
        r_pd = np.ascontiguousarray(r_pd, dtype=float)
        phi_p = np.empty(len(r_pd))
        g_pd = np.empty_like(r_pd)
        _mesh_phi_grad(r_pd, self._tri, self._pn, self._glo, self._gh, self._gn,
                       self._start, self._cand, phi_p, g_pd)
        return phi_p, g_pd

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
