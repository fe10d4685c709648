"""Closest points on segments and triangles, the numba primitives of the exact distances.

Shared by the level sets (:mod:`.polygon`, :mod:`.mesh`) and the boundary-element queries
(:mod:`ase_sphrelax.boundary`).
"""
from __future__ import annotations

import numba

__all__ = ["segment_distance2", "closest_on_triangle"]


@numba.njit(cache=True, inline="always")
def segment_distance2(px, py, ax, ay, ex, ey, inv_len2):
    """Squared distance from p to the segment a + t e, t in [0, 1], and the clamped t
    (``inv_len2 = 1 / |e|^2``)."""
    t = ((px - ax) * ex + (py - ay) * ey) * inv_len2
    if t < 0.0:
        t = 0.0
    elif t > 1.0:
        t = 1.0
    qx = ax + t * ex
    qy = ay + t * ey
    return (px - qx) ** 2 + (py - qy) ** 2, t


@numba.njit(cache=True)
def closest_on_triangle(px, py, pz, t):
    """Closest point on triangle t = (ax, ay, az, bx, ..., cz) to p (Ericson 5.1.5).

    Returns (dist^2, qx, qy, qz, feature) with feature 0/1/2 = vertex a/b/c,
    3/4/5 = edge ab/ac/bc, 6 = face interior.
    """
    ax, ay, az = t[0], t[1], t[2]
    abx, aby, abz = t[3] - ax, t[4] - ay, t[5] - az
    acx, acy, acz = t[6] - ax, t[7] - ay, t[8] - az
    apx, apy, apz = px - ax, py - ay, pz - az
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    u = 0.0
    v = 0.0
    feature = 6
    if d1 <= 0.0 and d2 <= 0.0:
        feature = 0
    else:
        bpx, bpy, bpz = px - t[3], py - t[4], pz - t[5]
        d3 = abx * bpx + aby * bpy + abz * bpz
        d4 = acx * bpx + acy * bpy + acz * bpz
        vc = d1 * d4 - d3 * d2
        if d3 >= 0.0 and d4 <= d3:
            u = 1.0
            feature = 1
        elif vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
            u = d1 / (d1 - d3)
            feature = 3
        else:
            cpx, cpy, cpz = px - t[6], py - t[7], pz - t[8]
            d5 = abx * cpx + aby * cpy + abz * cpz
            d6 = acx * cpx + acy * cpy + acz * cpz
            vb = d5 * d2 - d1 * d6
            va = d3 * d6 - d5 * d4
            if d6 >= 0.0 and d5 <= d6:
                v = 1.0
                feature = 2
            elif vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
                v = d2 / (d2 - d6)
                feature = 4
            elif va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
                w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
                u = 1.0 - w
                v = w
                feature = 5
            else:
                denom = 1.0 / (va + vb + vc)
                u = vb * denom
                v = vc * denom
    qx = ax + u * abx + v * acx
    qy = ay + u * aby + v * acy
    qz = az + u * abz + v * acz
    return (px - qx) ** 2 + (py - qy) ** 2 + (pz - qz) ** 2, qx, qy, qz, feature
