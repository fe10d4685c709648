"""declared_epsilon (Eq. 45, one construction for every method's particles) and nn_min_over_mean."""
import numpy as np
import pytest

from ase_sphrelax.analysis.alaric import declared_epsilon, nn_min_over_mean
from ase_sphrelax.domains import Circle


def _hex_disc(spacing):
    """A hexagonal lattice cut to the disc of radius 1 - spacing / 2."""
    k = np.arange(-40, 41)
    i, j = np.meshgrid(k, k)
    x = spacing * (i + 0.5 * j).ravel()
    y = spacing * (np.sqrt(3) / 2 * j).ravel()
    keep = np.hypot(x, y) < 1.0 - spacing / 2
    return np.stack([x[keep], y[keep]], axis=1)


def _random_disc(n, seed=0):
    rng = np.random.default_rng(seed)
    r, t = np.sqrt(rng.uniform(0, 1, n)), rng.uniform(0, 2 * np.pi, n)
    return np.stack([r * np.cos(t), r * np.sin(t)], axis=1)


def test_a_lattice_is_far_below_a_random_start_and_lower_with_mirror_ghosts_than_truncated():
    disc = Circle((0, 0), 1.0)
    lattice, rand = _hex_disc(0.08), _random_disc(len(_hex_disc(0.08)))
    uniform = lambda x: np.ones(len(x))  # noqa: E731
    eps = {(name, b): declared_epsilon(x, uniform, disc, 2, b)["epsilon"]
           for name, x in (("lattice", lattice), ("random", rand)) for b in ("mirror", "wall")}
    # measured: 1.4e-2 and 0.32 (the cut lattice's jagged edge is most of the 1.4e-2)
    assert eps[("lattice", "mirror")] < 0.1 * eps[("random", "mirror")]
    # the lattice's edge sits about half a spacing in: truncated kernels see half a neighbourhood there
    # (measured 1.4e-2 against 1.8e-2)
    assert eps[("lattice", "mirror")] < 0.9 * eps[("lattice", "wall")]


def test_independent_of_the_target_scale_and_of_3d_positions():
    disc = Circle((0, 0), 1.0)
    x = _random_disc(400, seed=2)
    one = declared_epsilon(x, lambda p: np.ones(len(p)), disc, 2)
    five = declared_epsilon(x, lambda p: np.full(len(p), 5.0), disc, 2)
    assert one["epsilon"] == pytest.approx(five["epsilon"], rel=1e-10)
    assert five["mass"] == pytest.approx(5.0 * one["mass"], rel=1e-10)
    x3 = np.zeros((400, 3))
    x3[:, :2] = x
    assert declared_epsilon(x3, lambda p: np.ones(len(p)), disc, 2)["epsilon"] == pytest.approx(one["epsilon"])


def test_nn_min_over_mean():
    grid = np.stack(np.meshgrid(np.arange(5.0), np.arange(5.0)), axis=-1).reshape(-1, 2)
    assert nn_min_over_mean(grid) == pytest.approx(1.0)
    paired = np.vstack([grid, grid[:1] + 1e-3])
    assert nn_min_over_mean(paired) < 0.01


def test_bad_input():
    disc = Circle((0, 0), 1.0)
    with pytest.raises(ValueError, match="boundary"):
        declared_epsilon(_random_disc(50), lambda p: np.ones(len(p)), disc, 2, boundary="ghost")
    with pytest.raises(ValueError, match="positions"):
        declared_epsilon(np.zeros(5), lambda p: np.ones(len(p)), disc, 2)
    with pytest.raises(ValueError, match="positions"):
        nn_min_over_mean(np.zeros((1, 2)))
