"""The small 3D BIPI scene the BIPI speed and memory tests share: a meshed sphere and random points in and
around it, with the support radius and skin they use."""
import numpy as np

from ase_sphrelax.boundary import BoundaryTriangles
from ase_sphrelax.domains import Sphere

H = 0.2
SKIN = 0.1 * H


def sphere():
    return BoundaryTriangles.from_domain(Sphere((0.0, 0.0, 0.0), 0.5).to_mesh(2))


def cloud(n, rng, scale=0.55):
    r = rng.uniform(-scale, scale, size=(4 * n, 3))
    return r[np.linalg.norm(r, axis=1) < scale][:n]
