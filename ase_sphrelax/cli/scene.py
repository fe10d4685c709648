"""Scenes of the command line: a domain (or the periodic interior), a spacing dx and the initial particles."""
from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

__all__ = ["BUILTIN_DOMAINS", "DOMAIN_HELP", "Scene", "make_scene"]

BUILTIN_DOMAINS = ("circle", "box", "sphere", "periodic")
BOX_LO, BOX_HI = 0.3125, 0.6875

DOMAIN_HELP = ("circle (Fan's, centre 0.5 0.5 radius 0.2), box ([0.3125, 0.6875]^dim, a whole number of default "
               "cells), sphere (centre 0.5, radius 0.2, "
               "3D), periodic (unit cell, interior case), or a path to an edge file ('x1 y1 x2 y2' per line) or a "
               "closed .stl mesh")


class Scene(NamedTuple):
    """What a command starts from; unpacks as ``domain, dx, atoms``."""

    domain: object  # a Domain, or None for the periodic interior
    dx: float
    atoms: object  # ase.Atoms

    @property
    def dim(self):
        """2 or 3: the domain's dimension, or that of the periodic box."""
        if self.domain is not None:
            return self.domain.dim
        return 3 if self.atoms.pbc[2] else 2


def make_scene(domain_name, dim=None, dx=None, jitter=0.1, seed=0, max_particles=None):
    """Domain (None for the periodic interior), dx and initial Atoms of a named scene or a geometry file.

    Parameters
    ----------
    domain_name : str
        One of :data:`BUILTIN_DOMAINS`, or the path of an edge file (2D) or a closed ``.stl`` mesh (3D).
    dim : {2, 3} or None
        Must match the domain; None: the domain's (2 for ``"periodic"`` and ``"box"``).
    dx : float or None
        Background cell size; None: 1/256 in 2D, 1/32 in 3D (files: extent/128 or extent/32).
    jitter, seed :
        Initial random shift as a fraction of dx, and its seed (:func:`ase_sphrelax.build.fill`).
    max_particles : float or None
        Print the fill's estimate (:func:`ase_sphrelax.cli.common.check_fill_size`) and refuse it past
        this; None: :func:`~ase_sphrelax.build.fill`'s default limit, nothing printed.

    Returns
    -------
    Scene
        The built-in scenes have ``N dx^d`` within 1 % of the domain volume at their default dx
        (circle 0.14 %, sphere 0.92 %, box and periodic exact; ``tests/test_scenes.py``).
    """
    import numpy as np

    from ..build import fill, periodic_box
    from ..domains import Box, Circle, Mesh, Polygon, Sphere

    if domain_name == "periodic":
        dim = dim or 2
        dx = dx or (1 / 256 if dim == 2 else 1 / 32)
        n = int(round(1.0 / dx))
        atoms = periodic_box(n, dx=dx, dim=dim, jitter=jitter, seed=seed)
        return Scene(None, dx, atoms)
    if domain_name == "circle":
        domain = Circle((0.5, 0.5), 0.2)
    elif domain_name == "sphere":
        domain = Sphere((0.5, 0.5, 0.5), 0.2)
    elif domain_name == "box":
        # 0.375 = 96/256 = 12/32: the default meshes fill it exactly, N dx^d = V (the former [0.3, 0.7]^3 held
        # 1728 dx^3 = 0.0527 of its 0.064 and got worse when relaxed)
        d = dim or 2
        domain = Box((BOX_LO,) * d, (BOX_HI,) * d)
    else:
        path = Path(domain_name)
        if not path.is_file():
            raise ValueError(f"--domain must be one of {BUILTIN_DOMAINS} or an existing edge/.stl file, "
                             f"got {domain_name!r}")
        domain = Mesh(str(path)) if path.suffix.lower() == ".stl" else Polygon.from_edges(path)
    if dim is not None and dim != domain.dim:
        raise ValueError(f"--dim {dim} does not match the {domain.dim}D domain {domain_name!r}")
    if dx is None:
        if domain_name in BUILTIN_DOMAINS:
            dx = 1 / 256 if domain.dim == 2 else 1 / 32
        else:
            lo, hi = domain.bounds
            dx = float(np.max(hi - lo)) / (128 if domain.dim == 2 else 32)
    # a box's mesh starts at its corner: N dx^d = V whenever the sides are whole numbers of dx
    origin = domain.bounds[0] if domain_name == "box" else None
    limit = {}
    if max_particles is not None:
        from .common import check_fill_size

        check_fill_size(domain, dx, max_particles)
        limit = dict(max_particles=max_particles)
    atoms = fill(domain, dx, jitter=jitter, seed=seed, origin=origin, **limit)
    return Scene(domain, dx, atoms)
