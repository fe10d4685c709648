"""3D boundaries as closed triangle meshes with unit inward normals (BIPI's no-boundary-particle
approach in 3D: the domain boundary is represented directly by triangles, Boregowda & Liu Sec. 2.1).

A :class:`BoundaryTriangles` wraps a watertight, consistently wound ``trimesh.Trimesh`` that
encloses a positive volume (the checks of :class:`~ase_sphrelax.domains.Mesh`); normals point
into the enclosed volume. Sources: :meth:`BoundaryTriangles.from_mesh` (a
:class:`~ase_sphrelax.domains.Mesh`), :meth:`~BoundaryTriangles.from_file` (STL, OBJ, PLY, ...
through trimesh), :meth:`~BoundaryTriangles.from_trimesh` and :meth:`~BoundaryTriangles.from_domain`
(meshes and 3D boxes; an analytic sphere has no triangles: mesh it, e.g.
``Mesh(trimesh.creation.icosphere(...))``). :meth:`~BoundaryTriangles.refine` splits large triangles
(trimesh's ``subdivide_to_size``).
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
    centroid_tc : ndarray (T, 3)
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
        """The enclosed region as a :class:`~ase_sphrelax.domains.Mesh` (inside tests, fill)."""
        if self._domain is None:
            from ..domains.mesh import Mesh

            self._domain = Mesh(self.trimesh)
        return self._domain

    def contains(self, r_pc):
        """Boolean mask of the points strictly inside."""
        return self.domain.contains(r_pc)

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
        out._domain = self._domain
        return out

    def __repr__(self):
        return (f"BoundaryTriangles({self.n_triangles} triangles, area {self.area_t.sum():.6g}, "
                f"volume {self.volume:.6g})")
