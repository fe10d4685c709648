"""Boundaries given by their elements, for boundary-integral SPH (Boregowda & Liu, BIPI).

* :class:`BoundarySegments` (2D straight segments) and :class:`BoundaryTriangles` (3D
  triangle meshes), with unit **inward** normals, lengths/areas and centroids; the public
  ``segments`` of :class:`~ase_sphrelax.domains.Polygon` (and 2D boxes, polygonal CSG) and
  ``triangles`` of :class:`~ase_sphrelax.domains.Mesh`.
* :class:`BoundaryQuery` / :func:`boundary_pairs`: the (particle, element) pairs within a
  radius, O(N + S) on the bins of the neighbour search, in CSR form over particles.
"""
from .query import BoundaryPairs, BoundaryQuery, boundary_pairs
from .segments import EDGE_TO_DX_RATIO, BoundarySegments, NoSegmentsError, OrientationWarning
from .triangles import BoundaryTriangles

__all__ = ["BoundarySegments", "BoundaryTriangles", "BoundaryQuery", "BoundaryPairs", "boundary_pairs",
           "OrientationWarning", "NoSegmentsError", "EDGE_TO_DX_RATIO"]
