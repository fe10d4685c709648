"""3D boundaries as closed triangle meshes with unit inward normals (BIPI's no-boundary-particle
approach in 3D: the domain boundary is represented directly by triangles, Boregowda & Liu Sec. 2.1).

A :class:`BoundaryTriangles` wraps a watertight, consistently wound ``trimesh.Trimesh`` that
encloses a positive volume (the checks of :class:`~ase_sphrelax.domains.Mesh`); normals point
into the enclosed volume. Sources: :meth:`BoundaryTriangles.from_mesh` (a
:class:`~ase_sphrelax.domains.Mesh`), :meth:`~BoundaryTriangles.from_file` (STL, OBJ, PLY, ...
through trimesh), :meth:`~BoundaryTriangles.from_trimesh` and :meth:`~BoundaryTriangles.from_domain`
(meshes and 3D boxes; an analytic sphere has no triangles: mesh it, e.g.
``Mesh(trimesh.creation.icosphere(...))``). :meth:`~BoundaryTriangles.refine` splits large triangles
(trimesh's ``subdivide_to_size``). :meth:`~BoundaryTriangles.with_cell` makes the mesh periodic along
some axes (:mod:`ase_sphrelax.boundary.periodic`).
"""
from __future__ import annotations

import os

import numpy as np

from .segments import EDGE_TO_DX_RATIO

__all__ = ["BoundaryTriangles"]


class BoundaryTriangles:
    """A closed triangle mesh with unit inward normals.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        Watertight, consistently wound, enclosing a positive volume (a negative volume is
        inverted).
    name : str, optional

    Attributes
    ----------
    vertices_tkc : ndarray (T, 3, 3)
        The three vertices of each triangle.
    normal_tc : ndarray (T, 3)
        Unit inward normals.
    area_t : ndarray (T,)
    surface : float
        Total area of the walls (of one period, for periodic triangles: images not counted).
    centroid_tc : ndarray (T, 3)
    periodic : PeriodicCell or None
        The periodic directions (:meth:`with_cell`), None when bounded; the elements are then the
        triangles of one period and their images around the cell.
    cell, pbc : ndarray (3, 3), ndarray of bool (3,)
        The periods as an ASE cell (zero rows along bounded axes) and the periodic axes; zeros
        and all False when bounded.
    pseudo_normal_tfc : ndarray (T, 7, 3)
        Inward angle-weighted pseudo-normals of the features of each triangle (vertices a, b,
        c, edges ab, ac, bc, face; Baerentzen & Aanaes 2005), for inside/outside decisions.
    packed_tk : ndarray (T, 9)
        Vertex coordinates flattened, for the numba loops.
    trimesh : trimesh.Trimesh
    """

    dim = 3

    def __init__(self, mesh, name=None):
        import trimesh

        from ..domains.mesh import check_volume, pseudo_normals

        if not isinstance(mesh, trimesh.Trimesh):
            raise TypeError(f"mesh must be a trimesh.Trimesh, got {type(mesh).__name__}")
        mesh = check_volume(mesh, name or "mesh")
        area = np.asarray(mesh.area_faces, dtype=float)
        if not np.all(area > 0):
            t = int(np.nonzero(~(area > 0))[0][0])
            raise ValueError(f"{name or 'mesh'}: triangle {t} has zero area")
        self.trimesh = mesh
        self.name = name
        self.vertices_tkc = np.ascontiguousarray(np.asarray(mesh.triangles, dtype=float))
        self.normal_tc = np.ascontiguousarray(-np.asarray(mesh.face_normals, dtype=float))
        self.area_t = area
        self.centroid_tc = self.vertices_tkc.mean(axis=1)
        self.pseudo_normal_tfc = np.ascontiguousarray(-pseudo_normals(mesh))
        self.packed_tk = np.ascontiguousarray(self.vertices_tkc.reshape(-1, 9))
        self._domain = None
        self.periodic = None
        self.cell = np.zeros((3, 3))
        self.pbc = np.zeros(3, dtype=bool)
        self.surface = float(np.sum(area))  # the walls' area (of one period, when periodic)

    # -- sources ------------------------------------------------------------------
    @classmethod
    def from_trimesh(cls, mesh, name=None):
        return cls(mesh, name=name)

    @classmethod
    def from_mesh(cls, mesh):
        """The triangles of a :class:`~ase_sphrelax.domains.Mesh`."""
        from ..domains.mesh import Mesh

        if not isinstance(mesh, Mesh):
            raise TypeError(f"mesh must be an ase_sphrelax.domains.Mesh, got {type(mesh).__name__}")
        out = cls(mesh.trimesh, name=repr(mesh))
        out._domain = mesh
        return out

    @classmethod
    def from_file(cls, path):
        """Read a closed mesh with trimesh (STL, OBJ, PLY, ...)."""
        import trimesh

        if not isinstance(path, (str, os.PathLike)):
            raise TypeError(f"path must be a file name, got {type(path).__name__}")
        suffix = os.path.splitext(os.fspath(path))[1].lower().lstrip(".")
        if suffix not in trimesh.available_formats():
            raise ValueError(f"{str(path)!r}: unknown file type {('.' + suffix) if suffix else '(no extension)'}: "
                             "an edge file needs .edges, .txt or .dat, a mesh .stl, .obj, .ply or another format "
                             "trimesh reads")
        try:
            mesh = trimesh.load(path, force="mesh")
        except Exception as err:  # trimesh raises many types
            raise ValueError(f"{str(path)!r}: cannot read a mesh (trimesh: {err})") from None
        return cls(mesh, name=str(path))

    @classmethod
    def from_domain(cls, domain):
        """Triangles of a 3D domain: a :class:`~ase_sphrelax.domains.Mesh` or a 3D Box."""
        import trimesh

        from ..domains.analytic import Ball, Box
        from ..domains.mesh import Mesh

        if isinstance(domain, BoundaryTriangles):
            return domain
        if isinstance(domain, Mesh):
            return cls.from_mesh(domain)
        if not hasattr(domain, "dim"):
            raise TypeError(f"cannot take boundary triangles of {type(domain).__name__}; accepted: Mesh, 3D Box "
                            "(or BoundaryTriangles.from_file / from_trimesh)")
        if domain.dim != 3:
            raise ValueError(f"boundary triangles are 3D; {type(domain).__name__} is {getattr(domain, 'dim', '?')}D "
                             "(use ase_sphrelax.boundary.BoundarySegments for 2D polygons)")
        if isinstance(domain, Box):
            box = trimesh.creation.box(extents=domain.hi - domain.lo)
            box.apply_translation(0.5 * (domain.lo + domain.hi))
            return cls(box, name=repr(domain))
        if isinstance(domain, Ball):
            from .segments import NoSegmentsError

            raise NoSegmentsError(
                f"{type(domain).__name__} is an analytic curved domain and has no boundary triangles; mesh it, e.g. "
                "Mesh(trimesh.creation.icosphere(subdivisions=4, radius=r)) translated to the centre, or "
                "domain.to_mesh(subdivisions)")
        raise TypeError(f"cannot take boundary triangles of {type(domain).__name__}; accepted: Mesh, 3D Box, a mesh file")

    # -- derived ------------------------------------------------------------------
    def __len__(self):
        return len(self.area_t)

    @property
    def n_triangles(self):
        return len(self.area_t)

    @property
    def bounds(self):
        b = np.asarray(self.trimesh.bounds, dtype=float)
        return b[0].copy(), b[1].copy()

    @property
    def volume(self):
        return float(self.trimesh.volume)


    @property
    def domain(self):
        """The enclosed region as a :class:`~ase_sphrelax.domains.Mesh` (inside tests, fill).

        Periodic triangles: a :class:`~ase_sphrelax.boundary.periodic.PeriodicDomain` (the mesh's
        images joined across the periodic faces, evaluated at wrapped positions)."""
        if self._domain is None:
            from ..domains.mesh import Mesh

            self._domain = Mesh(self.trimesh)
        return self._domain

    def contains(self, r_pc):
        """Boolean mask of the points strictly inside (periodic: the wrapped position)."""
        return self.domain.contains(r_pc)

    # -- periodic directions ---------------------------------------------------------
    def with_cell(self, pbc=True, cell=None, quiet=False, reach=1):
        """These triangles periodic along the axes ``pbc`` (ASE ``cell`` + ``pbc``).

        The mesh stays one period's closed region. Triangles lying on a periodic face (the
        planes ``x = lo`` and ``x = lo + L``, ``lo`` the mesh's lower bound, ``L`` the period)
        are dropped, with a :class:`~ase_sphrelax.boundary.periodic.PeriodicFacesWarning`
        saying how many; the others are moved by whole periods (by their centroid) into the cell
        ``[0, L)``. The elements are these triangles and their images ``-reach..reach`` periods
        away along every periodic axis, built once; their inside/outside pseudo-normals are those
        of the mesh's images joined across the faces, so the walls continue across the seam.
        Particles are wrapped into the cell (by the neighbour list of the same cell) and meet the
        images directly.

        Parameters
        ----------
        pbc : bool or sequence of 3 bool
            Periodic axes (x, y, z); ``True`` alone: all three.
        cell : None, float, sequence or (3, 3) array
            Periods (an ASE cell with its periodic vectors along their axes, or lengths);
            default (None or a zero length) the mesh's extent along the axis.
        quiet : bool
            No warning about dropped face triangles.
        reach : int
            Periods of images on each side (the kernel support must not exceed ``reach`` periods).

        Raises
        ------
        ValueError
            Bad ``pbc``/``cell``, a triangle that crosses a cell face after the move (cut the mesh
            at the faces), or images that do not join into a closed mesh (the faces' triangulations
            must match).
        """
        import trimesh

        from ..domains.mesh import Mesh, pseudo_normals
        from .periodic import PeriodicCell, PeriodicDomain

        base = BoundaryTriangles(self.trimesh, name=self.name) if self.periodic is not None else self
        lo, hi = base.bounds
        periodic = PeriodicCell(pbc, cell, lo, hi, 3, name=self.name or "mesh", reach=reach)
        out = BoundaryTriangles(base.trimesh, name=base.name)
        if not periodic.pbc.any():
            out._domain = base._domain
            return out
        period = periodic.period_c
        # whole periods: the mesh's lower bound into [0, L) (the same periodic region)
        move = -np.floor(np.where(periodic.pbc, lo / np.where(periodic.pbc, period, 1.0), 0.0)) * period
        vertices = np.asarray(base.trimesh.vertices, dtype=float) + move
        faces = np.asarray(base.trimesh.faces)
        v_tkc = vertices[faces]
        plane = lo + move
        on_lo = {i: np.all(np.abs(v_tkc[:, :, i] - plane[i]) <= periodic.tol, axis=1) for i in periodic.axes}
        on_hi = {i: np.all(np.abs(v_tkc[:, :, i] - plane[i] - period[i]) <= periodic.tol, axis=1)
                 for i in periodic.axes}
        face = np.zeros(len(faces), dtype=bool)
        for i in periodic.axes:
            face |= on_lo[i] | on_hi[i]
        if face.all():
            raise ValueError(f"{self.name}: every triangle lies on a periodic face ({periodic.label})")
        wall = np.nonzero(~face)[0]
        centroid = v_tkc[wall].mean(axis=1)
        jump = np.rint((periodic.wrap(centroid) - centroid) / np.where(periodic.pbc, period, 1.0)).astype(np.int64)
        for i in periodic.axes:
            x = v_tkc[wall, :, i] + (jump[:, i] * period[i])[:, None]
            bad = np.nonzero((x.min(axis=1) < -periodic.tol) | (x.max(axis=1) > period[i] + periodic.tol))[0]
            if len(bad):
                raise ValueError(f"{self.name}: triangle {int(wall[bad[0]])} crosses a periodic cell face along "
                                 f"{'xyz'[i]} (the cell is [0, {period[i]:.12g})); cut the mesh at the faces")
        # the images joined into one closed mesh (face triangles kept on its outermost planes only)
        lo_k = np.where(periodic.pbc, -reach - 1, 0)
        hi_k = np.where(periodic.pbc, reach, 0)
        copies = periodic.shifts(lo_k=lo_k, hi_k=hi_k)
        row = {tuple(k): m for m, k in enumerate(copies)}
        joined_v, joined_f, where = [], [], np.full((len(copies), len(faces)), -1, dtype=np.int64)
        count = 0
        for m, k in enumerate(copies):
            keep = ~face
            for i in periodic.axes:
                keep |= (on_lo[i] & (k[i] == lo_k[i])) | (on_hi[i] & (k[i] == hi_k[i]))
            where[m, keep] = count + np.arange(int(keep.sum()))
            joined_v.append(vertices + k * period)
            joined_f.append(faces[keep] + m * len(vertices))
            count += int(keep.sum())
        joined = trimesh.Trimesh(np.concatenate(joined_v), np.concatenate(joined_f), process=False)
        joined.merge_vertices()
        if not joined.is_watertight:
            raise ValueError(f"{self.name}: the images along {periodic.label} do not join into a closed mesh; the "
                             "triangulations of opposite periodic faces must match")
        pseudo = -pseudo_normals(joined)
        # the elements: the wall triangles (wrapped into the cell) and their images -reach..reach periods away
        images = periodic.shifts(reach)
        index = np.array([[where[row[tuple(k + j)], t] for t, j in zip(wall, jump)] for k in images]).ravel()
        out.vertices_tkc = np.ascontiguousarray(joined.triangles[index])
        out.normal_tc = np.ascontiguousarray(np.tile(base.normal_tc[wall], (len(images), 1)))
        out.area_t = np.tile(base.area_t[wall], len(images))
        out.centroid_tc = out.vertices_tkc.mean(axis=1)
        out.pseudo_normal_tfc = np.ascontiguousarray(pseudo[index])
        out.packed_tk = np.ascontiguousarray(out.vertices_tkc.reshape(-1, 9))
        out.periodic, out.cell, out.pbc = periodic, periodic.cell, periodic.pbc
        out.surface = float(np.sum(base.area_t[wall]))
        out._domain = PeriodicDomain(base.domain, Mesh(joined), periodic)
        if not quiet:
            periodic.warn_dropped(int(face.sum()), self.name or "mesh", "triangles")
        return out

    def refine(self, max_edge=None, dx=None, ratio=EDGE_TO_DX_RATIO):
        """Split triangles until no edge is longer than ``max_edge`` (or ``dx / ratio``).

        Uses ``trimesh.remesh.subdivide_to_size`` (midpoint subdivision, the surface is
        unchanged). The exact boundary integrals do not depend on the triangulation.
        """
        import trimesh

        from ..checks import check_positive

        if max_edge is None:
            if dx is None:
                raise ValueError("refine needs max_edge or dx (max_edge = dx / ratio)")
            max_edge = check_positive("dx", dx) / check_positive("ratio", ratio)
        max_edge = check_positive("max_edge", max_edge)
        v, f = trimesh.remesh.subdivide_to_size(self.trimesh.vertices, self.trimesh.faces, max_edge, max_iter=50)
        out = BoundaryTriangles(trimesh.Trimesh(v, f), name=self.name)
        if self.periodic is not None:
            return out.with_cell(self.pbc, self.cell, quiet=True, reach=self.periodic.reach)
        out._domain = self._domain
        return out

    def __repr__(self):
        periodic = "" if self.periodic is None else f", periodic in {self.periodic.label}"
        return (f"BoundaryTriangles({self.n_triangles} triangles, area {self.area_t.sum():.6g}, "
                f"volume {self.volume:.6g}{periodic})")
