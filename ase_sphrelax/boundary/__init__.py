"""Boundaries given by their elements, for boundary-integral SPH (Boregowda & Liu, BIPI).

* :class:`BoundarySegments` (2D straight segments) and :class:`BoundaryTriangles` (3D
  triangle meshes), with unit **inward** normals, lengths/areas and centroids; built from the
  domains (``BoundarySegments.from_domain`` of a :class:`~ase_sphrelax.domains.Polygon`, 2D box or
  polygonal CSG, ``BoundaryTriangles.from_domain`` of a :class:`~ase_sphrelax.domains.Mesh` or 3D
  box), edge files, vertex loops or mesh files. Boundaries stand above the domains: they import
  the domains' public loop and distance helpers (:mod:`~ase_sphrelax.domains.loops`,
  :mod:`~ase_sphrelax.domains.closest`), never the reverse.
* :class:`BoundaryQuery` / :func:`boundary_pairs`: the (particle, element) pairs within a
  radius, O(N + S) on the bins of the neighbour search, in CSR form over particles.
* :func:`gamma_and_gradient` / :class:`BoundaryIntegrals`: the kernel volume fraction
  ``gamma_a`` and ``grad gamma_a`` (BIPI Eq. 2-3) from a boundary-integral identity, exact
  (closed forms in 2D; singular part in closed form, Gauss on smooth remainders in 3D), plus
  the per-element terms.
"""
from .gamma import BoundaryIntegrals, BoundaryTerms, as_boundary, boundary_terms, gamma_and_gradient
from .query import BoundaryPairs, BoundaryQuery, boundary_pairs
from .segments import EDGE_TO_DX_RATIO, BoundarySegments, NoSegmentsError, OrientationWarning
from .triangles import BoundaryTriangles

__all__ = ["BoundarySegments", "BoundaryTriangles", "BoundaryQuery", "BoundaryPairs", "boundary_pairs",
           "OrientationWarning", "NoSegmentsError", "EDGE_TO_DX_RATIO", "BoundaryIntegrals", "BoundaryTerms",
           "gamma_and_gradient", "boundary_terms", "as_boundary"]
