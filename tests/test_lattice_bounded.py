"""Non-periodic pattern classification (Fan Sec. 5.2): lattice patches cut to a circle."""
import numpy as np
import pytest

from ase import Atoms
from ase_sphrelax.analysis.bounded import classify_bounded_pattern, hexatic_order, local_lattice_patterns
from ase_sphrelax.analysis import pattern_cell
from ase_sphrelax.domains import Circle


def disc_of(pattern, params=None, radius=12.0, noise=0.0, seed=0, angle=0.4):
    cell, _ = pattern_cell(pattern, params)
    c, s = np.cos(angle), np.sin(angle)
    cell = cell @ np.array([[c, s], [-s, c]])
    m = np.arange(-40, 41)
    m1, m2 = np.meshgrid(m, m)
    pts = m1.reshape(-1, 1) * cell[0] + m2.reshape(-1, 1) * cell[1]
    pts = pts[np.linalg.norm(pts, axis=1) < radius]
    pts = pts + np.random.default_rng(seed).normal(0.0, noise, pts.shape)
    atoms = Atoms(f"X{len(pts)}", positions=np.c_[pts, np.zeros(len(pts))], pbc=False)
    return atoms, Circle((0.0, 0.0), radius)


@pytest.mark.parametrize("pattern,params", [("hexagonal", {}), ("square", {}), ("rectangular", {"k": 1.3}),
                                            ("diamond", {"k": 2.39}), ("diamond", {"k": 1.22}),
                                            ("parallelogram", {"k": 1.12, "r": 0.37})])
@pytest.mark.parametrize("noise", [0.0, 0.01])
def test_classify_lattice_patch(pattern, params, noise):
    atoms, domain = disc_of(pattern, params, noise=noise)
    found, info = classify_bounded_pattern(atoms, domain, margin=2.0)
    assert found == pattern
    assert info["fractions"][pattern] > 0.8


def test_hexatic_orders_separate_hexagonal_and_square():
    hexa, _ = disc_of("hexagonal")
    square, _ = disc_of("square")
    inner = lambda a: np.linalg.norm(a.positions[:, :2], axis=1) < 8.0
    assert hexatic_order(hexa.positions, 6, inner(hexa)) == pytest.approx(1.0, abs=1e-9)
    assert hexatic_order(square.positions, 4, inner(square)) == pytest.approx(1.0, abs=1e-9)
    assert hexatic_order(square.positions, 6, inner(square)) < 0.5


def test_disordered_points_are_mixed():
    rng = np.random.default_rng(0)
    pts = rng.random((2000, 2)) * 40.0
    labels = local_lattice_patterns(pts)
    assert max(np.mean(labels == name) for name in set(labels)) < 0.9
