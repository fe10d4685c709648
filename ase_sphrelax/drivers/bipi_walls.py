"""Packed wall particles: BIPI on the solid side of the walls (issue 17 item 3).

The paper packs the solid of its airfoil with the same method as the fluid (Boregowda & Liu 2025);
here the solid is the band of the walls that an SPH engine with wall particles needs:

    band = (fluid offset outward by ``layers dx``) minus fluid  [intersected with ``clip``]

built with shapely (``buffer`` with round joins, so the band is exactly the set
``0 < phi <= layers dx`` up to the chords of its arcs; ``phi`` the fluid's signed distance). Its
boundary contains the fluid-side walls themselves. :class:`~ase_sphrelax.drivers.bipi_packer.BIPIPacker`
packs the band like any domain (Step 1 fill, Steps 2a-2c), so the wall particles sit on layers
parallel to the walls at about ``(j + 1/2) dx``, ``j = 0 .. layers - 1``, instead of on the
Cartesian grid (:func:`~ase_sphrelax.drivers.bipi_packer.wall_particles`). A particle never leaves
the band (the packer's rule), so no wall particle is inside the fluid.

Only 2D (polygonal boundaries).
"""
from __future__ import annotations

import warnings

import numpy as np
from ase import Atoms

from ..checks import check_positive
from .bipi_packer import WALL, add_walls, wall_layers

__all__ = ["wall_band", "packed_wall_particles", "add_packed_walls", "WALL_MODES"]

WALL_MODES = ("packed", "grid")
ARC_SEGMENTS = 16  # shapely quad_segs: segments per quarter circle of the band's rounded corners


def wall_band(boundary, dx, layers=None, h=None, clip=None, quad_segs=ARC_SEGMENTS):
    """The solid band of ``layers`` dx outside the walls, as BoundarySegments.

    Parameters
    ----------
    boundary : BoundarySegments, 2D polygonal domain or edge file
        The fluid region.
    dx : float
    layers : int or None
        Band thickness in units of ``dx``; default ``ceil(h / dx)``
        (:func:`~ase_sphrelax.drivers.bipi_packer.wall_layers`).
    h : float or None
        Kernel support, for the default ``layers``.
    clip : shapely geometry or None
        The band is intersected with it (e.g. ``shapely.box(-1e9, -1e9, 1e9, depth)``: no wall
        above a free surface).
    quad_segs : int
        Segments per quarter circle of the rounded corners.

    Returns
    -------
    BoundarySegments
        The band; ``.domain`` is its Polygon.
    """
    from ..boundary import BoundarySegments, as_boundary

    dx = check_positive("dx", dx)
    layers = _layers(layers, h, dx)
    fluid_boundary = as_boundary(boundary)
    if fluid_boundary.dim != 2:
        raise ValueError(f"boundary: packed walls need a 2D polygonal boundary, got dim={fluid_boundary.dim}")
    fluid = fluid_boundary.domain.to_shapely()
    band = fluid.buffer(layers * dx, quad_segs=int(quad_segs)).difference(fluid)
    if clip is not None:
        band = band.intersection(clip)
    band = _polygons(band, min_area=1e-6 * dx * dx)
    if band.is_empty:
        raise ValueError("clip: nothing of the wall band is left inside it")
    return BoundarySegments.from_shapely(band, name=f"wall band ({layers} layers)")


def packed_wall_particles(boundary, dx, layers=None, h=None, clip=None, pack_h=None, quiet=True, **packer_kwargs):
    """Wall particles BIPI-packed in :func:`wall_band` (Step 1 fill and Steps 2a-2c).

    Parameters
    ----------
    boundary, dx, layers, h, clip
        As for :func:`wall_band`.
    pack_h : float or None
        Support of the band's packing; default ``h``, else 4 dx (the paper's h_B / dx_r = 2).
    quiet : bool
        Silence the packer's not-converged warning (the verdict is kept in ``info``).
    **packer_kwargs
        Passed to :class:`~ase_sphrelax.drivers.bipi_packer.BIPIPacker` (caps, ``window``, ...).

    Returns
    -------
    ase.Atoms
        The wall particles, ``arrays["type"] = WALL``, at z = 0; ``info``: ``wall_layers``,
        ``wall_mode = "packed"``, ``wall_converged``, ``wall_reason``, ``wall_iterations_2a``,
        ``wall_iterations_2c``.
    """
    from .bipi_packer import pack

    dx = check_positive("dx", dx)
    layers = _layers(layers, h, dx)
    band = wall_band(boundary, dx, layers=layers, h=h, clip=clip)
    support = pack_h if pack_h is not None else (h if h is not None else 4.0 * dx)
    with warnings.catch_warnings():
        if quiet:
            warnings.simplefilter("ignore")
        packed, packer, _ = pack(band, dx, h=support, **packer_kwargs)
    converged, reason = packer.verdict()
    summary = packer.summary()
    walls = Atoms(positions=packed.positions, pbc=False)
    walls.arrays["type"] = np.full(len(walls), WALL, dtype=int)
    walls.info.update(dx=dx, wall_layers=layers, wall_mode="packed", wall_converged=bool(converged),
                      wall_reason=reason, wall_iterations_2a=summary["iterations_2a"],
                      wall_iterations_2c=summary["iterations_2c"], wall_pack_h=float(support))
    return walls


def add_packed_walls(atoms, boundary, dx, layers=None, h=None, clip=None, walls=None, **packer_kwargs):
    """``atoms`` (fluid) followed by :func:`packed_wall_particles` (or the given ``walls``).

    As :func:`~ase_sphrelax.drivers.bipi_packer.add_walls` (``type`` FLUID then WALL,
    ``info["n_fluid"]``, ``info["n_wall"]``); pass ``walls`` to reuse one packing of the walls
    for several fluid starts.
    """
    if walls is None:
        walls = packed_wall_particles(boundary, dx, layers=layers, h=h, clip=clip, **packer_kwargs)
    out = add_walls(atoms, boundary, dx, walls=walls)
    out.info.update({k: v for k, v in walls.info.items() if k.startswith("wall_")})
    return out


def _layers(layers, h, dx):
    if layers is None:
        if h is None:
            raise ValueError("give layers (an integer >= 1) or h (the kernel support) for the default ceil(h/dx)")
        return wall_layers(h, dx)
    if isinstance(layers, bool) or not isinstance(layers, (int, np.integer)) or layers < 1:
        raise ValueError(f"layers must be an integer >= 1, got {layers!r}")
    return int(layers)


def _polygons(geometry, min_area):
    """The polygons of a shapely result (lines and points of a touching clip dropped), slivers removed."""
    import shapely

    parts, todo = [], [geometry]
    while todo:
        g = todo.pop()
        if hasattr(g, "geoms"):
            todo.extend(g.geoms)
        elif isinstance(g, shapely.Polygon) and g.area > min_area:
            parts.append(g)
    return shapely.MultiPolygon(parts) if len(parts) > 1 else (parts[0] if parts else shapely.Polygon())
