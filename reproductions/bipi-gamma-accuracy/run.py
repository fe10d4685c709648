"""Accuracy of BIPI's kernel volume fraction γ and its gradient ∇γ against independent quadratures.

    python reproductions/bipi-gamma-accuracy/run.py --out reproductions/bipi-gamma-accuracy/results

Writes ``results.json.gz`` (gzipped JSON; every point: class, shape, position, our values, the reference, errors) and
``README.md`` (a table of the largest errors per point class) in ``--out``. Backs the accuracy
figures of docs/guides/bipi.md. Kernel: Wendland C2 with support ``h`` (the project's default).

**2D reference: direct polar integration.** γ(x) = ∫_Ω∩B(x,h) W(|y - x|) dy written in polar
coordinates about x: along the ray of angle θ the parts inside the polygon are found from the ray's
crossings with every edge, each part classified by shapely's ``contains_xy`` at its midpoint, and the
radial integrals are closed polynomials (Ψ(t) = ∫_0^t W r dr); ∇γ(x) = ∫ ∇_x W dy = -∫ e(θ) ∫ W'(r) r dr
dθ over the same parts, so neither uses the boundary (divergence) identity of the code under test. The
θ integral is scipy's adaptive ``quad_vec`` between breakpoints (the angles of the vertices within h
and of the circle |y - x| = h crossing the edges), to 1e-15 absolute.

**3D reference: face quadrature.** Along each ray from x the inside parts enter and leave through
faces, so γ(x) = χ(x) + Σ_f D_f ∫_f (M(min(h, r)) - M(h)) / r^3 dA, with M(r) = ∫_0^r W s^2 ds,
D_f = (y - x)·n_f (outward n_f, constant over the face) and χ the solid-angle fraction of the
interior seen from x (1 inside, 0 outside, 1/2 on a face, α/2π on an edge of interior dihedral angle
α, the spherical excess / 4π at a vertex); ∇γ = -Σ_f n_f ∫_f W dA. Each face integral is taken in
polar coordinates about the foot of x on the face's plane, over the three signed triangles (foot,
v_i, v_i+1): the radial integrals are closed polynomials, the angle is scipy's adaptive ``quad``
(split where the edge is closest to the foot and where it leaves the support), to 1e-15. The same idea
as tests/test_gamma_3d_exact.py, written separately (angles about the foot instead of the edge
parameter) and extended to points on faces, edges and vertices. χ of a convex polyhedron comes from
its face planes. Known values checked first: 1 deep inside, 1/2 on a face, the half-space profile.

Point classes (2D: a concave L, a square with a square hole, a 10° wedge, a sliver triangle 1e-3 h
wide; 3D: a tetrahedron, a box, an icosphere), h = 0.4, distances in units of h:

* inside / outside: within h of the boundary, at least 1e-3 h from it;
* on edges, on vertices (2D also the vertices of holes);
* near edges: 1e-12 .. 1e-2 h from an edge, both sides;
* edge lines: 1e-12 .. 1e-3 h from the line through an edge, 0.02 .. 0.9 h beyond its end vertex, both
  sides (where issue 17 found γ wrong);
* convex / concave corners: 1e-9 .. 0.5 h from a vertex in random directions;
* 10° wedge: inside the wedge, 1e-9 .. 0.5 h from its tip; sliver: inside and around the sliver;
* 3D: near faces (1e-12 .. 0.5 h, both sides), on faces, near and on edges, near and on vertices,
  edge lines.

Errors: absolute |γ - γ_ref| and h |∇γ - ∇γ_ref|_max (∇γ in units of 1/h); relative ones divide by
|γ_ref| and by h |∇γ_ref|_max, over the points where these are at least 1e-6 (elsewhere a relative
error says nothing).
"""
from __future__ import annotations

import argparse
import gzip
import json
import math
import platform
import sys
import time
import warnings
from pathlib import Path

import numpy as np
from numpy.polynomial import polynomial as P

H = 0.4
REL_FLOOR = 1e-6
FLAG = 1e-12  # README lists every point whose absolute error exceeds this (issue 17's target)
EPS_ABS = 2e-14  # 3D, per quadrature interval; below this the adaptive rules chase rounding noise
EXACT_ZERO = 1e-40  # 160-bit geometry (3D): below this a distance is the working precision's noise, i.e. zero
EPS_ABS_2D = 1e-13  # quad_vec adds a round-off term of about 50 eps times the integral of |f| to its estimate
F_POLY = P.polymul(P.polypow([1.0, -1.0], 4), [1.0, 4.0])  # Wendland C2 profile (1 - q)^4 (1 + 4 q), q = r / h


def _kernel_polys(dim):
    """(W, Ψ = ∫ W r^(d-1) dr, ∫ W' r^(d-1) dr) as polynomials in q, normalised to ∫ W = 1 in ``dim`` dims."""
    r_pow = [0.0] * (dim - 1) + [1.0]
    sphere = 2.0 * math.pi if dim == 2 else 4.0 * math.pi
    sigma = 1.0 / (sphere * P.polyval(1.0, P.polyint(P.polymul(F_POLY, r_pow))))
    w = sigma * F_POLY
    return w, P.polyint(P.polymul(w, r_pow)), P.polyint(P.polymul(P.polyder(w), r_pow))


W2, PSI2, DPSI2 = _kernel_polys(2)
W3, M3, _ = _kernel_polys(3)  # M(q) = ∫_0^q W s^2 ds
M3_ONE = P.polyval(1.0, M3)
PHI3 = P.polyint(M3[2:])  # ∫ M(r) / r^2 dr (M ~ r^3 at 0)
PSI3_FACE = P.polyint(P.polymul(W3, [0.0, 1.0]))  # ∫ W r dr


# -- 2D: direct polar integration ------------------------------------------------------------------------------------
def _ray_terms(theta, x, a_sc, d_sc, polygon):
    """[γ, ∇γ_x, ∇γ_y] integrands of the ray of angle θ from x (lengths in units of h)."""
    import shapely

    e = np.array([math.cos(theta), math.sin(theta)])
    den = e[0] * d_sc[:, 1] - e[1] * d_sc[:, 0]
    ax = a_sc - x
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (ax[:, 0] * d_sc[:, 1] - ax[:, 1] * d_sc[:, 0]) / den
        s = (ax[:, 0] * e[1] - ax[:, 1] * e[0]) / den
    hit = (den != 0.0) & (t > 0.0) & (t < 1.0) & (s >= 0.0) & (s <= 1.0)
    ts = np.unique(np.concatenate([[0.0], t[hit], [1.0]]))
    mid = 0.5 * (ts[:-1] + ts[1:])
    inside = shapely.contains_xy(polygon, x[0] + mid * e[0], x[1] + mid * e[1])
    t0, t1 = ts[:-1][inside], ts[1:][inside]
    gamma = float(np.sum(P.polyval(t1, PSI2) - P.polyval(t0, PSI2)))
    radial = float(np.sum(P.polyval(t1, DPSI2) - P.polyval(t0, DPSI2)))
    return np.array([gamma, -e[0] * radial, -e[1] * radial])


def _breakpoints_2d(x, a_sc, d_sc):
    """Angles where the ray integrand is not smooth: vertices within h, the circle of radius h crossing edges."""
    angles = []
    for v in a_sc:
        r = v - x
        dist = math.hypot(*r)
        if 0.0 < dist < 1.0:
            angles.append(math.atan2(r[1], r[0]))
    ax = a_sc - x  # |ax + s d|^2 = 1
    qa = np.einsum("sc,sc->s", d_sc, d_sc)
    qb = 2.0 * np.einsum("sc,sc->s", ax, d_sc)
    qc = np.einsum("sc,sc->s", ax, ax) - 1.0
    disc = qb * qb - 4.0 * qa * qc
    for k in np.nonzero(disc >= 0.0)[0]:
        for sign in (-1.0, 1.0):
            s = (-qb[k] + sign * math.sqrt(disc[k])) / (2.0 * qa[k])
            if 0.0 <= s <= 1.0:
                r = ax[k] + s * d_sc[k]
                angles.append(math.atan2(r[1], r[0]))
    angles = np.sort(np.mod(np.asarray(angles, dtype=float), 2.0 * math.pi))
    start = angles[0] if len(angles) else 0.0
    return np.concatenate([angles, [start + 2.0 * math.pi]]) if len(angles) else np.array([0.0, 2.0 * math.pi])


def graded(cuts):
    """``cuts`` with extra breakpoints at 10^-1 .. 10^-15 of each interval's length from both of its ends.

    Near a breakpoint the integrands change on the scale of x's distance to an edge or vertex (down to
    1e-12 h here): an adaptive rule whose first nodes all lie farther out never sees that change, and its
    error estimate stays small while it misses an O(distance) part (measured: a 2D point 1e-9 h from an
    edge lost 9e-10 of γ without this grading).
    """
    cuts = np.asarray(cuts, dtype=float)
    fractions = 10.0 ** -np.arange(1, 16)
    out = [cuts]
    for lo, hi in zip(cuts[:-1], cuts[1:]):
        out += [lo + (hi - lo) * fractions, hi - (hi - lo) * fractions]
    out = np.concatenate(out)
    return out[np.argsort((out - cuts[0]) / (cuts[-1] - cuts[0]))] if cuts[-1] != cuts[0] else cuts


def reference_2d(x, polygon):
    """γ and h ∇γ at ``x`` (units of h) for a shapely polygon (units of h); returns (values, error estimate)."""
    from scipy.integrate import quad_vec

    a_sc, d_sc = [], []
    for ring in [polygon.exterior, *polygon.interiors]:
        v = np.asarray(ring.coords)[:-1]
        a_sc.append(v)
        d_sc.append(np.roll(v, -1, axis=0) - v)
    a_sc, d_sc = np.concatenate(a_sc), np.concatenate(d_sc)
    cuts = graded(_breakpoints_2d(x, a_sc, d_sc))
    total, err = np.zeros(3), 0.0
    for lo, hi in zip(cuts[:-1], cuts[1:]):
        if hi - lo <= 0.0:
            continue
        value, e = quad_vec(_ray_terms, lo, hi, args=(x, a_sc, d_sc, polygon), epsabs=EPS_ABS_2D, epsrel=1e-14,
                            norm="max", limit=2000)
        total += value
        err += e
    return total, err


def shapes_2d():
    """Name -> shapely polygon (lengths in units of h)."""
    import shapely

    s = 1.0 / H
    wedge = math.radians(10.0)
    return {
        "L (concave)": shapely.Polygon(np.array([[0, 0], [1.0, 0], [1.0, 0.5], [0.5, 0.5], [0.5, 1.0], [0, 1.0]]) * s),
        "square with hole": shapely.Polygon(np.array([[0, 0], [1.0, 0], [1.0, 1.0], [0, 1.0]]) * s,
                                            [np.array([[0.35, 0.35], [0.35, 0.6], [0.6, 0.6], [0.6, 0.35]]) * s]),
        "10 deg wedge": shapely.Polygon([[0.0, 0.0], [3.0 * math.cos(wedge / 2), -3.0 * math.sin(wedge / 2)],
                                         [3.0 * math.cos(wedge / 2), 3.0 * math.sin(wedge / 2)]]),
        "sliver": shapely.Polygon([[0.0, 0.0], [2.0, -5e-4], [2.0, 5e-4]]),
    }


def _corner_kind(prev_v, v, next_v):
    """Loops run with the domain on their left (outer counter-clockwise, holes clockwise): a left turn is convex."""
    u, w = v - prev_v, next_v - v
    turn = float(u[0] * w[1] - u[1] * w[0])
    return "convex corner" if turn > 0 else "concave corner"


def points_2d(polygon, name, rng, n):
    """(class, x) pairs (units of h) around one polygon."""
    import shapely

    out = []
    rings = [(np.asarray(polygon.exterior.coords)[:-1], False)] + [(np.asarray(r.coords)[:-1], True)
                                                                    for r in polygon.interiors]
    # shapely rings may be either orientation: make exteriors counter-clockwise, holes clockwise
    rings = [(v if (shapely.LinearRing(v).is_ccw != hole) else v[::-1], hole) for v, hole in rings]
    edges = [(v[i], v[(i + 1) % len(v)]) for v, _ in rings for i in range(len(v))]
    corners = [(v[i - 1], v[i], v[(i + 1) % len(v)]) for v, _ in rings for i in range(len(v))]
    boundary = polygon.boundary

    def unit(u):
        return u / np.linalg.norm(u)

    for _ in range(n):  # on edges, near edges
        a, b = edges[rng.integers(len(edges))]
        base = a + rng.uniform(0.02, 0.98) * (b - a)
        out.append(("on edge", base))
        nrm = unit(np.array([-(b - a)[1], (b - a)[0]]))
        out.append(("near edge", base + rng.choice([-1, 1]) * 10.0 ** rng.uniform(-12, -2) * nrm))
    for a, b in edges:  # edge lines beyond each end vertex, both sides
        for end, other in ((b, a), (a, b)):
            along = unit(end - other)
            nrm = np.array([-along[1], along[0]])
            for _ in range(max(1, n // len(edges))):
                beyond = rng.uniform(0.02, 0.9)
                for side in (-1.0, 1.0):
                    out.append(("edge line", end + beyond * along + side * 10.0 ** rng.uniform(-12, -3) * nrm))
    for prev_v, v, next_v in corners:
        kind = _corner_kind(prev_v, v, next_v)
        out.append(("on vertex", v.copy()))
        for _ in range(max(2, n // len(corners))):
            phi = rng.uniform(0, 2 * math.pi)
            out.append((kind, v + 10.0 ** rng.uniform(-9, math.log10(0.5)) * np.array([math.cos(phi), math.sin(phi)])))
    lo, hi = np.array(polygon.bounds[:2]) - 1.0, np.array(polygon.bounds[2:]) + 1.0
    found = {"inside": 0, "outside": 0} if name != "sliver" else {}  # the sliver is thinner than 1e-3 h
    while found and min(found.values()) < n:  # within h of the boundary, at least 1e-3 h from it
        x = rng.uniform(lo, hi)
        dist = boundary.distance(shapely.Point(x))
        if not 1e-3 <= dist < 1.0:
            continue
        kind = "inside" if polygon.contains(shapely.Point(x)) else "outside"
        if found[kind] < n:
            found[kind] += 1
            out.append((kind, x))
    if name == "10 deg wedge":
        half = math.radians(5.0)
        for _ in range(n):
            phi = rng.uniform(-0.999 * half, 0.999 * half)
            out.append(("10 deg wedge", 10.0 ** rng.uniform(-9, math.log10(0.5)) * np.array([math.cos(phi), math.sin(phi)])))
    if name == "sliver":  # across the sliver (5e-4 h half width) and just outside it
        for _ in range(n):
            s = rng.uniform(0.05, 1.95)
            out.append(("sliver", np.array([s, rng.uniform(-1.0, 1.0) * 5e-4 * s / 2.0 + rng.choice([0, 1]) * 1e-3])))
    return out


# -- 3D: face quadrature ---------------------------------------------------------------------------------------------
def _face_geometry(x, v_kc):
    """Distance d = (v_0 - x)·n of x from the face's plane (outward n from the winding) and, per edge of the
    face, (foot-to-line distance, angle of v_i, signed sweep v_i -> v_i+1, direction of the perpendicular)
    in the plane about the foot of x. Computed with 160-bit mpmath from the double inputs: near an edge,
    d and the foot's distance to the edge's line are both tiny and their ratio decides the solid angle,
    which double arithmetic gets only to eps |x| / distance (1e-4 relative at 1e-12 h)."""
    import mpmath as mp

    with mp.workprec(160):
        X = mp.matrix([float(c) for c in x])
        V = [mp.matrix([float(c) for c in v]) for v in v_kc]

        def cross(a, b):
            return mp.matrix([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])

        def dot(a, b):
            return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]

        n = cross(V[1] - V[0], V[2] - V[0])
        n = n / mp.sqrt(dot(n, n))
        d = dot(V[0] - X, n)
        d = mp.mpf(0) if abs(d) < EXACT_ZERO else d
        foot = X + d * n
        u = (V[1] - V[0]) / mp.sqrt(dot(V[1] - V[0], V[1] - V[0]))
        w = cross(n, u)  # (u, w, n) right-handed: angles about n counter-clockwise
        p_k2 = [(dot(v - foot, u), dot(v - foot, w)) for v in V]
        edges = []
        for i in range(3):
            (ax, ay), (bx, by) = p_k2[i], p_k2[(i + 1) % 3]
            abx, aby = bx - ax, by - ay
            c = ax * aby - ay * abx
            dist = abs(c) / mp.sqrt(abx ** 2 + aby ** 2)  # foot to the edge's line
            dist = mp.mpf(0) if dist < EXACT_ZERO else dist
            sign = 1 if c >= 0 else -1
            edges.append((float(dist), float(mp.atan2(ay, ax)), float(mp.atan2(ax * by - ay * bx, ax * bx + ay * by)),
                          float(mp.atan2(-abx * sign, aby * sign))))
        return float(d), edges


def _face_terms(x, v_kc, n_c):
    """(D ∫ (M(min(1, r)) - M(1)) / r^3 dA, ∫ W dA) over one triangle (outward unit normal n_c), units of h."""
    from scipy.integrate import quad

    if abs(float((v_kc[0] - x) @ n_c)) >= 1.0 + 1e-9:
        return 0.0, 0.0, 0.0
    d, edges = _face_geometry(x, v_kc)
    if abs(d) >= 1.0:
        return 0.0, 0.0, 0.0
    rho_clip = math.sqrt(max(1.0 - d * d, 0.0))
    solid = plain = 0.0
    err = 0.0
    for dist, phi_a, sweep, normal_dir in edges:
        if dist <= 1e-300:
            continue

        def rho_edge(phi, phi_n=normal_dir, dist=dist):
            c = math.cos(phi - phi_n)
            return dist / c if c > 0.0 else math.inf

        cuts = [0.0, sweep]
        if sweep == 0.0:
            continue
        turns = [normal_dir]  # where the edge is closest to the foot, and where it leaves the support
        if dist < rho_clip:
            half = math.acos(dist / rho_clip)
            turns += [normal_dir - half, normal_dir + half]
        for turn in turns:
            off = math.remainder(turn - phi_a, 2 * math.pi)
            if 0.0 < off / sweep < 1.0:
                cuts.append(off)
        cuts = graded(sorted(cuts, key=lambda c: c / sweep))

        def radial(phi, which):
            rho = min(rho_edge(phi_a + phi), rho_clip)
            hi = min(math.sqrt(d * d + rho * rho), 1.0)
            lo = abs(d)
            if which == 0:
                if d == 0.0:
                    return 0.0
                return d * (P.polyval(hi, PHI3) - P.polyval(lo, PHI3)) + M3_ONE * (d / hi - math.copysign(1.0, d))
            return P.polyval(hi, PSI3_FACE) - P.polyval(lo, PSI3_FACE)

        for lo_c, hi_c in zip(cuts[:-1], cuts[1:]):
            for which in (0, 1):
                value, e = quad(radial, lo_c, hi_c, args=(which,), epsabs=EPS_ABS, epsrel=1e-14, limit=500)
                err += e
                if which == 0:
                    solid += value
                else:
                    plain += value
    return solid, plain, err


def plane_distances(x, mesh):
    """(v_0 - x)·n of every face (outward n), exact in sign (mpmath, :func:`_face_geometry`) below 1e-9 h."""
    d_f = np.einsum("fc,fc->f", mesh.vertices[mesh.faces[:, 0]] - x, mesh.face_normals)
    for f in np.nonzero(np.abs(d_f) < 1e-9)[0]:
        d_f[f] = _face_geometry(x, mesh.vertices[mesh.faces[f]])[0]
    return d_f


def reference_3d(x, mesh):
    """γ and h ∇γ at ``x`` (units of h) for a convex trimesh mesh in units of h; (values, error estimate)."""
    gamma, grad, err = chi_3d(x, mesh, plane_distances(x, mesh)), np.zeros(3), 0.0
    for f, (v_kc, n_c) in enumerate(zip(mesh.vertices[mesh.faces], mesh.face_normals)):
        if np.any(x < v_kc.min(axis=0) - 1.0) or np.any(x > v_kc.max(axis=0) + 1.0):
            continue
        solid, plain, e = _face_terms(x, v_kc, n_c)
        gamma += solid
        grad -= plain * n_c
        err += e
    return np.concatenate([[gamma], grad]), err


def shapes_3d():
    import trimesh

    return {"tetrahedron": trimesh.convex.convex_hull([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]]),
            "box": trimesh.creation.box(extents=(1.6, 1.2, 2.0)),
            "icosphere": trimesh.creation.icosphere(subdivisions=1, radius=1.2)}


def chi_3d(x, mesh, d_f):
    """Solid-angle fraction of a convex mesh's interior at ``x`` (units of h) from the faces' plane distances
    ``d_f`` (:func:`plane_distances`): 0 or 1 off the surface; 1/2 on a face; α / 2π on an edge (interior
    dihedral α); the spherical excess / 4π at a vertex."""
    if np.any(d_f < 0):
        return 0.0
    touching = np.nonzero(d_f == 0.0)[0]
    if len(touching) == 0:
        return 1.0
    # the surface faces through x: the interior is the cone of the half-spaces of their distinct planes
    normals = np.unique(np.round(mesh.face_normals[touching], 12), axis=0)
    if len(normals) == 1:
        return 0.5
    if len(normals) == 2:
        return (math.pi - math.acos(np.clip(normals[0] @ normals[1], -1, 1))) / (2 * math.pi)
    v = np.nonzero(np.linalg.norm(mesh.vertices - x, axis=1) < 1e-12)[0]
    if len(v) != 1:
        raise ValueError("x touches three planes but is not a vertex")
    edges = mesh.face_adjacency_edges
    at_v = np.nonzero((edges == v[0]).any(axis=1))[0]
    alpha = math.pi - mesh.face_adjacency_angles[at_v]  # interior dihedral angles of the edges at v
    return float((alpha.sum() - (len(at_v) - 2) * math.pi) / (4 * math.pi))


def points_3d(mesh, rng, n):
    """(class, x) pairs (units of h) around one convex mesh."""
    out = []
    tri = mesh.vertices[mesh.faces]

    def unit(u):
        return u / np.linalg.norm(u)

    def random_dir():
        return unit(rng.normal(size=3))

    for _ in range(n):
        f = rng.integers(len(tri))
        bary = rng.dirichlet([2.0, 2.0, 2.0])
        base = bary @ tri[f]
        out.append(("on face", base))
        out.append(("near face", base + rng.choice([-1, 1]) * 10.0 ** rng.uniform(-12, math.log10(0.5)) * mesh.face_normals[f]))
    edges = mesh.face_adjacency_edges
    for _ in range(n):
        k = rng.integers(len(edges))
        a, b = mesh.vertices[edges[k]]
        base = a + rng.uniform(0.02, 0.98) * (b - a)
        out.append(("on edge", base))
        side = unit(np.cross(b - a, random_dir()))
        out.append(("near edge", base + 10.0 ** rng.uniform(-12, -2) * side))
        end, other = (b, a) if rng.random() < 0.5 else (a, b)
        out.append(("edge line", end + rng.uniform(0.02, 0.9) * unit(end - other)
                    + 10.0 ** rng.uniform(-12, -3) * unit(np.cross(end - other, random_dir()))))
    for _ in range(n):
        v = mesh.vertices[rng.integers(len(mesh.vertices))]
        out.append(("on vertex", v.copy()))
        out.append(("near vertex", v + 10.0 ** rng.uniform(-9, math.log10(0.5)) * random_dir()))
    return out


# -- measurement -----------------------------------------------------------------------------------------------------
def measure(points, ours_fn, ref_fn):
    rows = []
    for (kind, shape, x) in points:
        ref, ref_err = ref_fn(shape, x)
        got = ours_fn(shape, x)
        g_abs = abs(got[0] - ref[0])
        d_abs = float(np.abs(got[1:] - ref[1:]).max())
        d_scale = float(np.abs(ref[1:]).max())
        rows.append(dict(point_class=kind, shape=shape, x_over_h=[float(v) for v in x],
                         gamma=float(got[0]), gamma_ref=float(ref[0]), grad_h=[float(v) for v in got[1:]],
                         grad_h_ref=[float(v) for v in ref[1:]], ref_error_estimate=float(ref_err),
                         gamma_abs=float(g_abs), grad_abs=d_abs,
                         gamma_rel=float(g_abs / abs(ref[0])) if abs(ref[0]) >= REL_FLOOR else None,
                         grad_rel=float(d_abs / d_scale) if d_scale >= REL_FLOOR else None))
    return rows


def summarise(rows):
    """Per point class: count and the largest absolute / relative errors."""
    table = {}
    for kind in dict.fromkeys(r["point_class"] for r in rows):
        sel = [r for r in rows if r["point_class"] == kind]

        def worst(key, sel=sel):
            values = [r[key] for r in sel if r[key] is not None]
            return max(values) if values else None

        table[kind] = dict(n=len(sel), shapes=sorted({r["shape"] for r in sel}), gamma_abs=worst("gamma_abs"),
                           gamma_rel=worst("gamma_rel"), grad_abs=worst("grad_abs"), grad_rel=worst("grad_rel"),
                           ref_error_estimate=worst("ref_error_estimate"))
    table["all"] = dict(n=len(rows), gamma_abs=max(r["gamma_abs"] for r in rows),
                        gamma_rel=max(r["gamma_rel"] for r in rows if r["gamma_rel"] is not None),
                        grad_abs=max(r["grad_abs"] for r in rows),
                        grad_rel=max(r["grad_rel"] for r in rows if r["grad_rel"] is not None),
                        ref_error_estimate=max(r["ref_error_estimate"] for r in rows))
    return table


def relative_where_large(rows, floor=1e-4):
    """Largest relative errors over the points whose reference is at least ``floor`` (|γ_ref|, h max|∇γ_ref|)."""
    gamma = [r["gamma_rel"] for r in rows if r["gamma_rel"] is not None and abs(r["gamma_ref"]) >= floor]
    grad = [r["grad_rel"] for r in rows if r["grad_rel"] is not None and max(map(abs, r["grad_h_ref"])) >= floor]
    return dict(floor=floor, n_gamma=len(gamma), gamma_rel=max(gamma, default=None), n_grad=len(grad),
                grad_rel=max(grad, default=None))


def check_references():
    """Known values: the references themselves, before they judge anything."""
    import shapely

    big = shapely.Polygon([[-5, -5], [5, -5], [5, 5], [-5, 5]])
    inner, _ = reference_2d(np.zeros(2), big)
    half, _ = reference_2d(np.array([0.0, 5.0]), big)
    quarter, _ = reference_2d(np.array([5.0, 5.0]), big)
    box = shapes_3d()["box"]
    box.apply_scale(1.0 / H)
    deep, _ = reference_3d(np.zeros(3), box)
    top = np.array([0.0, 0.0, 1.0 / H])
    face, _ = reference_3d(top, box)
    x = top - np.array([0.0, 0.0, 0.3])  # 0.3 h inside the top face: the half-space profile
    marginal = 2.0 * math.pi * P.polysub([P.polyval(1.0, PSI3_FACE)], PSI3_FACE)  # ∫ W over a plane at distance z
    expected = 0.5 + P.polyval(0.3, P.polyint(marginal))
    near, _ = reference_3d(x, box)
    checks = dict(gamma_2d_inside=float(inner[0]), gamma_2d_on_edge=float(half[0]), gamma_2d_on_square_corner=float(quarter[0]),
                  gamma_3d_inside=float(deep[0]), gamma_3d_on_face=float(face[0]),
                  gamma_3d_at_0p3h=float(near[0]), gamma_3d_at_0p3h_expected=float(expected),
                  grad_3d_at_0p3h_z=float(near[3]), grad_3d_at_0p3h_z_expected=float(-P.polyval(0.3, marginal)))
    errors = [abs(inner[0] - 1), abs(half[0] - 0.5), abs(quarter[0] - 0.25), abs(deep[0] - 1), abs(face[0] - 0.5),
              abs(near[0] - expected), abs(near[3] + P.polyval(0.3, marginal))]
    checks["max_error"] = float(max(errors))
    if checks["max_error"] > 1e-13:
        raise RuntimeError(f"reference quadratures fail their known values: {checks}")
    return checks


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="reproductions/bipi-gamma-accuracy/results")
    parser.add_argument("--n", type=int, default=6, help="points per class and shape (roughly)")
    parser.add_argument("--seed", type=int, default=17)
    parser.add_argument("--readme-only", action="store_true", help="rewrite README.md from the existing results.json.gz")
    args = parser.parse_args(argv)
    if args.readme_only:
        with gzip.open(Path(args.out) / "results.json.gz", "rt") as fh:
            results = json.load(fh)
        (Path(args.out) / "README.md").write_text(readme(results))
        return results
    import shapely
    import trimesh  # noqa: F401

    from ase_sphrelax.boundary import BoundarySegments, BoundaryTriangles, gamma_and_gradient

    warnings.filterwarnings("ignore", category=RuntimeWarning)
    rng = np.random.default_rng(args.seed)
    t0 = time.perf_counter()
    checks = check_references()
    print(f"reference quadratures on known values: max error {checks['max_error']:.1e}", flush=True)

    polys = shapes_2d()
    seg = {name: BoundarySegments.from_shapely(shapely.affinity.scale(p, H, H, origin=(0, 0)), name=name)
           for name, p in polys.items()}
    pts2 = [(kind, name, x) for name, p in polys.items() for kind, x in points_2d(p, name, rng, args.n)]

    def ours_2d(name, x):
        g, d = gamma_and_gradient(np.array([[x[0] * H, x[1] * H, 0.0]]), seg[name], H)
        return np.array([g[0], d[0, 0] * H, d[0, 1] * H])

    t = time.perf_counter()
    rows2 = measure(pts2, ours_2d, lambda name, x: reference_2d(x, polys[name]))
    print(f"2D: {len(rows2)} points in {time.perf_counter() - t:.0f} s", flush=True)

    meshes = shapes_3d()
    tris = {name: BoundaryTriangles.from_trimesh(m.copy(), name=name) for name, m in meshes.items()}
    unit_meshes = {}
    for name, m in meshes.items():
        u = m.copy()
        u.apply_scale(1.0 / H)
        unit_meshes[name] = u
    pts3 = [(kind, name, x) for name, m in unit_meshes.items() for kind, x in points_3d(m, rng, args.n)]

    def ref_3d(name, x):
        return reference_3d(x, unit_meshes[name])

    def ours_3d(name, x):
        g, d = gamma_and_gradient(np.array([x * H]), tris[name], H)
        return np.concatenate([[g[0]], d[0] * H])

    t = time.perf_counter()
    rows3 = measure(pts3, ours_3d, ref_3d)
    print(f"3D: {len(rows3)} points in {time.perf_counter() - t:.0f} s", flush=True)

    results = dict(command="python " + " ".join([Path(sys.argv[0]).as_posix()] + sys.argv[1:]), h=H, seed=args.seed,
                   n=args.n, kernel="wendland_c2", relative_floor=REL_FLOOR, reference_checks=checks,
                   summary_2d=summarise(rows2), summary_3d=summarise(rows3),
                   relative_where_ref_at_least_1e4=relative_where_large(rows2 + rows3), points_2d=rows2, points_3d=rows3,
                   wall_time_s=time.perf_counter() - t0, python=platform.python_version())
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "results.json.gz", "wb") as raw, gzip.GzipFile(fileobj=raw, mode="wb", filename="", mtime=0) as fh:
        fh.write(json.dumps(results, indent=1).encode())
    (out / "README.md").write_text(readme(results))
    print(readme(results))
    return results


def _fmt(v):
    return "—" if v is None else f"{v:.1e}"


def readme(results):
    lines = ["# Accuracy of γ and ∇γ (BIPI Eq. 2–3) against independent quadratures", "",
             f"    {results['command']}", "",
             "Written by `reproductions/bipi-gamma-accuracy/run.py` (its docstring describes the references and the points).",
             f"Support h = {results['h']:g}, Wendland C2, seed {results['seed']}. Errors: |γ − γ_ref| and "
             "h max|∇γ − ∇γ_ref| (absolute); relative: divided by |γ_ref| and h max|∇γ_ref|, over the points where "
             f"these are ≥ {results['relative_floor']:g}. The references checked first on known values (γ = 1, 1/2, "
             f"1/4, the half-space profile in 3D): max error {results['reference_checks']['max_error']:.1e}. "
             "`ref err` is the quadrature's own error estimate (the largest over the class). "
             f"Wall time {results['wall_time_s']:.0f} s.", ""]
    for dim in ("2d", "3d"):
        good = [r for r in results[f"points_{dim}"] if r["gamma_abs"] <= FLAG and r["grad_abs"] <= FLAG]
        n_all = len(results[f"points_{dim}"])
        lines.append(f"{dim.upper()}: {len(good)} of {n_all} points within {FLAG:g}; over those, the largest errors are "
                     f"{max(r['gamma_abs'] for r in good):.1e} (γ) and {max(r['grad_abs'] for r in good):.1e} (h ∇γ)."
                     + ("" if len(good) == n_all else " The others are listed at the end."))
        lines.append("")
    for dim in ("2d", "3d"):
        summary = results[f"summary_{dim}"]
        lines += [f"## {dim.upper()}", "",
                  "| points | n | shapes | γ abs | γ rel | ∇γ abs (× h) | ∇γ rel | ref err |", "|---|---|---|---|---|---|---|---|"]
        for kind, row in summary.items():
            shapes = ", ".join(row.get("shapes", ["all"]))
            lines.append(f"| {kind} | {row['n']} | {shapes} | {_fmt(row['gamma_abs'])} | {_fmt(row['gamma_rel'])} | "
                         f"{_fmt(row['grad_abs'])} | {_fmt(row['grad_rel'])} | {_fmt(row['ref_error_estimate'])} |")
        lines.append("")
    bad = [(dim, r) for dim in ("2d", "3d") for r in results[f"points_{dim}"]
           if r["gamma_abs"] > FLAG or r["grad_abs"] > FLAG]
    lines += [f"## Points with an absolute error above {FLAG:g}", ""]
    if not bad:
        lines.append("None.")
    else:
        lines += ["| dim | points | shape | x / h | γ | γ_ref | h ∇γ abs error |", "|---|---|---|---|---|---|---|"]
        for dim, r in bad:
            lines.append(f"| {dim.upper()} | {r['point_class']} | {r['shape']} | {[float(f'{v:.17g}') for v in r['x_over_h']]} | "
                         f"{r['gamma']:.16g} | {r['gamma_ref']:.16g} | {r['grad_abs']:.1e} |")
    lines.append("")
    return "\n".join(lines)


if __name__ == "__main__":
    main()
