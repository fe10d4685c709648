"""Accuracy and speed of exact vs tabulated level sets.

Usage::

    python -m ase_sphrelax.domains.benchmark FILE.edges [FILE.edges ...]

For each polygon (and a subdivided icosphere mesh) prints the build time,
the time per 1e4 random points of ``phi_and_normal`` in the bounding box,
and for the tabulated mode (grid spacing = size / 256, 512, 1024) the
maximum and median ``|phi_tab - phi_exact|`` within 3 dx of the boundary.
"""
from __future__ import annotations

import sys
import time

import numpy as np

from .mesh import Mesh
from .polygon import Polygon


def _time(f, r, repeat=5):
    f(r[:10])
    t = time.perf_counter()
    for _ in range(repeat):
        f(r)
    return (time.perf_counter() - t) / repeat


def compare(domain, name, n_points=10_000, divisions=(256, 512, 1024), seed=0):
    lo, hi = domain.bounds
    r = lo + (hi - lo) * np.random.default_rng(seed).random((n_points, domain.dim))
    t_exact = _time(domain.phi_and_normal, r)
    p_exact = domain.phi(r)
    print(f"{name}: {domain!r}: exact {1e3 * t_exact:.2f} ms per {n_points} points")
    size = float((hi - lo).max())
    for nd in divisions:
        dx = size / nd
        t = time.perf_counter()
        tab = domain.tabulated(dx)
        t_build = time.perf_counter() - t
        t_tab = _time(tab.phi_and_normal, r)
        err = np.abs(tab.phi(r) - p_exact)[np.abs(p_exact) < 3 * dx]
        print(f"  tabulated dx = size/{nd}: build {t_build:.2f} s, {1e3 * t_tab:.2f} ms, "
              f"near-boundary error max {err.max() / dx:.3f} dx, median {np.median(err) / dx:.2e} dx")


def main(argv=None):
    import trimesh

    for path in (sys.argv[1:] if argv is None else argv):
        compare(Polygon.from_edges(path), path)
    compare(Mesh(trimesh.creation.icosphere(subdivisions=3)), "icosphere(3)",
            n_points=2000, divisions=(32, 64))


if __name__ == "__main__":
    main()
