"""Checks of a flow start's scales, before any run: the spacing ``dx``, the support ``h``, the unit system.

Shared by :func:`ase_sphrelax.settle` and lammps_io's flow helpers (``hydrostatic_tank``,
``elliptic_drop``). Each failed check is a one-line ValueError naming the parameter (prefixed by
``who`` when given) and what is accepted.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["SPACING_FACTOR", "H_OVER_DX_RANGE", "G_SI", "DEPTH_RANGE_M", "C0_RANGE", "TANK_KE_LIMIT",
           "median_spacing", "check_spacing", "check_unit_scale"]

#: ``dx`` must lie within this factor of the fluid's median nearest-neighbour distance
SPACING_FACTOR = 1.5
#: ``h / dx`` (``h`` the kernel support radius) accepted
H_OVER_DX_RANGE = (1.5, 6.0)
#: the water depth in metres (lengths converted with ``G_SI / g``) must lie in ``DEPTH_RANGE_M``
G_SI, DEPTH_RANGE_M = 9.81, (1e-3, 20.0)
#: ``c0 / sqrt(g H)`` accepted (10 is Mach 0.1)
C0_RANGE = (3.0, 1000.0)
#: a tank at rest is unstable when its kinetic energy exceeds this fraction of ``M g H`` (settled tanks: below
#: 1e-4; alpha = 0.1 runs of reproductions/bipi-fig13-14 that went unstable: above 0.1)
TANK_KE_LIMIT = 1e-2


def _prefix(who):
    return f"{who}: " if who else ""


def median_spacing(x_pc):
    """The median nearest-neighbour distance of the points ``x_pc`` (N >= 2, any dimension)."""
    from scipy.spatial import cKDTree

    d, _ = cKDTree(x_pc).query(x_pc, k=2)
    return float(np.median(d[:, 1]))


def check_spacing(x_pc, h, dx, who=""):
    """``dx`` the spacing of the fluid points ``x_pc`` (within :data:`SPACING_FACTOR`; skipped for N < 2) and
    ``h`` within :data:`H_OVER_DX_RANGE` ``dx``; a swapped ``h`` and ``dx`` is named as such."""
    pre = _prefix(who)
    if len(x_pc) >= 2:
        spacing = median_spacing(x_pc)
        if not spacing / SPACING_FACTOR <= dx <= spacing * SPACING_FACTOR:
            hint = " (h and dx swapped?)" if abs(h / spacing - 1.0) < 0.5 or dx > 2.5 * spacing else ""
            raise ValueError(f"{pre}dx = {dx:g} but the fluid particles are spaced about {spacing:.4g} (median "
                             f"nearest-neighbour distance): dx must be the particle spacing{hint}")
    lo, hi = H_OVER_DX_RANGE
    if not lo <= h / dx <= hi:
        hint = " (h and dx swapped?)" if h < dx else ""
        raise ValueError(f"{pre}h = {h:g} is {h / dx:.3g} dx; h is the kernel support radius and must be "
                         f"{lo:g}-{hi:g} dx{hint}")


def check_unit_scale(depth, g, c0=None, who="", escape=""):
    """The water ``depth`` in metres (with ``g`` taken as m/s^2) within :data:`DEPTH_RANGE_M`, and ``c0`` (if
    given) within :data:`C0_RANGE` ``sqrt(g H)``: a tank in mm makes ``c0`` absurd. ``escape``: text appended
    to the depth message (how to run a tank that deep anyway)."""
    pre = _prefix(who)
    metres = depth * G_SI / g
    if not DEPTH_RANGE_M[0] <= metres <= DEPTH_RANGE_M[1]:
        raise ValueError(f"{pre}the water is {depth:.4g} deep, {metres:.4g} m with g = {g:g} taken as m/s^2 "
                         f"(allowed {DEPTH_RANGE_M[0]:g}-{DEPTH_RANGE_M[1]:g} m), so c0 ~ 10 sqrt(g H) would be "
                         f"absurd: lengths, g and c0 must be in one unit system (a tank in mm? give metres{escape})")
    if c0 is not None:
        mach = c0 / math.sqrt(g * depth)
        if not C0_RANGE[0] <= mach <= C0_RANGE[1]:
            raise ValueError(f"{pre}c0 = {c0:g} is {mach:.3g} sqrt(g H) (g = {g:g}, depth H = {depth:.4g}); it "
                             f"must be {C0_RANGE[0]:g}-{C0_RANGE[1]:g} sqrt(g H) (10 is Mach 0.1): lengths, g "
                             "and c0 must be in one unit system")
