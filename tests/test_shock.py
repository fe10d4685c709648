"""The shock-front radius per direction and its spread (ase_sphrelax.analysis.shock) on synthetic rings."""
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ase_sphrelax.analysis.shock import angular_modes, relative_positions, shock_isotropy, shock_radii

R0, WIDTH, EPS = 0.25, 0.01, 0.05
CELL = np.diag([1.0, 1.0, 1.0])
PBC2 = (True, True, False)


def ring(n=40000, eps=EPS, centre=(0.9, 0.1), seed=0):
    """Random points in the periodic unit square; a Gaussian ridge at R(theta) = R0 (1 + eps cos 4 theta)."""
    rng = np.random.default_rng(seed)
    r_pc = np.zeros((n, 3))
    r_pc[:, :2] = rng.uniform(0, 1, (n, 2))
    d = r_pc[:, :2] - np.asarray(centre)
    d -= np.round(d)
    theta = np.arctan2(d[:, 1], d[:, 0])
    front = R0 * (1 + eps * np.cos(4 * theta))
    value = 1.0 + 3.0 * np.exp(-(((np.hypot(d[:, 0], d[:, 1]) - front) / WIDTH) ** 2))
    return r_pc, value, np.array([*centre, 0.0])


def test_peak_follows_the_ridge_across_the_periodic_boundary():
    r_pc, value, centre = ring()
    angles, radius = shock_radii(r_pc, value, centre, cell=CELL, pbc=PBC2, n_angles=32, dr=0.005, r_max=0.45)
    theta = angles[:, 0]
    # the bin mean of R(theta) over a bin of width 2 pi / 32
    half = math.pi / 32
    expected = R0 * (1 + EPS * np.cos(4 * theta) * math.sin(4 * half) / (4 * half))
    assert np.all(np.isfinite(radius))
    assert np.max(np.abs(radius - expected)) < 0.005  # one radial bin
    iso = shock_isotropy(r_pc, value, centre, cell=CELL, pbc=PBC2, n_angles=32, dr=0.005, r_max=0.45)
    assert iso["spread"] == pytest.approx(np.std(expected) / np.mean(expected), abs=3e-3)
    assert iso["spread"] == pytest.approx(EPS / math.sqrt(2) * math.sin(4 * half) / (4 * half), abs=3e-3)
    assert iso["mean_radius"] == pytest.approx(R0, abs=2e-3)


def test_without_periodic_images_the_ridge_is_lost():
    """The centre sits near a corner: without the minimum image the measured fronts are wrong."""
    r_pc, value, centre = ring()
    wrong = shock_isotropy(r_pc, value, centre, n_angles=32, dr=0.005, r_max=0.45)
    right = shock_isotropy(r_pc, value, centre, cell=CELL, pbc=PBC2, n_angles=32, dr=0.005, r_max=0.45)
    assert right["spread"] < 0.05 < wrong["spread"] or wrong["empty_bins"] > 0


def test_a_circular_ridge_has_a_small_spread():
    r_pc, value, centre = ring(eps=0.0, centre=(0.5, 0.5))
    iso = shock_isotropy(r_pc, value, centre, cell=CELL, pbc=PBC2, n_angles=32, dr=0.005, r_max=0.45)
    assert iso["spread"] < 0.01
    assert iso["empty_bins"] == 0


def test_threshold_gives_the_outer_edge_of_the_ridge():
    r_pc, value, centre = ring()
    angles, radius = shock_radii(r_pc, value, centre, cell=CELL, pbc=PBC2, n_angles=32, method="threshold",
                                 threshold=2.0)
    # 1 + 3 exp(-x^2) = 2 at x = sqrt(ln 3); the outermost particle above it is within a small gap of it
    edge = R0 * (1 + EPS * np.cos(4 * angles[:, 0])) + WIDTH * math.sqrt(math.log(3.0))
    assert np.max(np.abs(radius - edge)) < 0.006


def test_spherical_shell_in_3d():
    rng = np.random.default_rng(1)
    r_pc = rng.uniform(0, 1, (80000, 3))
    centre = np.array([0.5, 0.5, 0.5])
    r = np.linalg.norm(r_pc - centre, axis=1)
    value = 1.0 + 3.0 * np.exp(-(((r - 0.3) / 0.02) ** 2))
    iso = shock_isotropy(r_pc, value, centre, cell=CELL, pbc=(True, True, True), dim=3, n_angles=8, dr=0.01,
                         r_max=0.45)
    assert len(iso["radius_k"]) == 8 * 4
    assert iso["mean_radius"] == pytest.approx(0.3, abs=0.005)
    assert iso["spread"] < 0.02


def test_empty_bins_are_nan_and_left_out():
    r_pc = np.array([[0.1, 0.0, 0.0], [0.2, 0.0, 0.0], [0.0, 0.31, 0.0]])
    iso = shock_isotropy(r_pc, np.array([1.0, 2.0, 5.0]), np.zeros(3), n_angles=4, dr=0.05)
    assert iso["empty_bins"] == 2
    assert iso["radius_k"][0] == pytest.approx(0.225)  # the bin of the larger value, at its centre
    assert iso["radius_k"][1] == pytest.approx(0.325)
    assert math.isfinite(iso["spread"])


@settings(max_examples=25, deadline=None, database=None)
@given(shift=st.tuples(st.integers(-3, 3), st.integers(-3, 3)), frac=st.floats(0.0, 1.0))
def test_periodic_translation_leaves_the_radii(shift, frac):
    """Moving every particle and the centre by a lattice vector (plus the same offset) changes nothing."""
    r_pc, value, centre = ring(n=5000)
    offset = np.array([shift[0] + frac, shift[1] - frac, 0.0])
    _, a = shock_radii(r_pc, value, centre, cell=CELL, pbc=PBC2, n_angles=16, dr=0.01)
    _, b = shock_radii(r_pc + offset, value, centre + offset, cell=CELL, pbc=PBC2, n_angles=16, dr=0.01)
    np.testing.assert_allclose(a, b, atol=1e-9)


@pytest.mark.parametrize("kwargs, match", [
    (dict(method="median", dr=0.1), "method must be one of"),
    (dict(n_angles=3, dr=0.1), "n_angles must be an integer >= 4"),
    (dict(n_angles=8.0, dr=0.1), "n_angles must be an integer >= 4"),
    (dict(), "dr must be a positive finite number"),
    (dict(method="threshold", threshold=float("nan")), "threshold must be a finite number or None"),
    (dict(method="centroid", threshold="high"), "threshold must be a finite number or None"),
    (dict(dr=0.1, r_max=-1.0), "r_max must be a positive finite number or None"),
    (dict(dr=0.1, pbc=(True, True, False)), "cell is needed"),
    (dict(dr=0.1, dim=4), "dim must be 2 or 3"),
])
def test_bad_input_is_one_line(kwargs, match):
    r_pc, value, centre = ring(n=100)
    with pytest.raises((ValueError, TypeError), match=match):
        shock_radii(r_pc, value, centre, **kwargs)


def test_bad_shapes():
    with pytest.raises(ValueError, match="value_p must have shape"):
        shock_radii(np.zeros((5, 3)), np.zeros(4), np.zeros(3), dr=0.1)
    with pytest.raises(ValueError, match="r_pc must have shape"):
        relative_positions(np.zeros(5), np.zeros(3))
    with pytest.raises(ValueError, match="centre must hold 2"):
        relative_positions(np.zeros((5, 3)), [0.0])
    with pytest.raises(ValueError, match="orthogonal"):
        relative_positions(np.zeros((5, 3)), np.zeros(3), cell=[[1, 0.5, 0], [0, 1, 0], [0, 0, 1]], pbc=(True, True, False))


def test_angular_modes_pick_the_harmonic():
    r_pc, value, centre = ring()
    angles, radius = shock_radii(r_pc, value, centre, cell=CELL, pbc=PBC2, n_angles=32, dr=0.005, r_max=0.45)
    a = angular_modes(angles, radius, modes=(2, 4, 6))
    half = math.pi / 32
    assert a[4] == pytest.approx(EPS * math.sin(4 * half) / (4 * half), abs=5e-3)
    assert a[2] < 5e-3 and a[6] < 5e-3
    theta = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    exact = angular_modes(theta, 2.0 * (1 + 0.1 * np.cos(6 * theta + 0.3)), modes=(6, 4))
    assert exact[6] == pytest.approx(0.1, rel=1e-12) and exact[4] == pytest.approx(0.0, abs=1e-12)
    with pytest.raises(ValueError, match="modes must be integers >= 1"):
        angular_modes(theta, theta, modes=(0,))
    with pytest.raises(ValueError, match="one entry per bin"):
        angular_modes(theta, theta[:-1])


def test_centroid_finds_the_middle_of_a_symmetric_ridge():
    r_pc, value, centre = ring()
    half = math.pi / 32
    for threshold in (None, 2.0):
        angles, radius = shock_radii(r_pc, value, centre, cell=CELL, pbc=PBC2, n_angles=32, method="centroid",
                                     threshold=threshold, r_max=0.45)
        expected = R0 * (1 + EPS * np.cos(4 * angles[:, 0]) * math.sin(4 * half) / (4 * half))
        assert np.max(np.abs(radius - expected)) < 2.5e-3  # a quarter of the ridge width: sampling noise


def test_automatic_threshold_is_midway_to_the_ridge():
    """ambient 1, ridge top 4: the automatic level is 2.5, the edge where 3 exp(-x^2) = 1.5."""
    r_pc, value, centre = ring(eps=0.0, centre=(0.5, 0.5))
    _, auto = shock_radii(r_pc, value, centre, n_angles=16, method="threshold")
    _, fixed = shock_radii(r_pc, value, centre, n_angles=16, method="threshold", threshold=2.5)
    np.testing.assert_allclose(auto, fixed, atol=2e-3)
    assert np.nanmean(fixed) == pytest.approx(R0 + WIDTH * math.sqrt(math.log(2.0)), abs=1.5e-3)
