"""A kernel defined in this test file, registered once, and run by Fan and ALARIC with FD-exact forces.

The toy kernel is a two-piece C2 spline: f = 1 - (120/17) q^2 + (128/17) q^3 for q < 1/2 and
(48/17) (1 - q)^4 for 1/2 <= q < 1 (value, slope and curvature match at q = 1/2, f'(0) = 0). The code
normalises it (sigma) and generates its numba closed forms; nothing else of the package names it.
Also: the generated closed forms of every registered kernel and dimension against the definition's
polynomials in q (value and four derivatives, near q = 1 and at the piece breaks).
"""
import math
from fractions import Fraction

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from ase import Atoms
from ase.calculators.fd import calculate_numerical_forces
from numpy.polynomial import polynomial as P
from scipy.integrate import quad

from ase_sphrelax import ALARICCalculator, FanCalculator
from ase_sphrelax.domains import Circle
from ase_sphrelax.kernels import KERNEL_NAMES, get_kernel, register_kernel

TOY = "toy_spline"
_C = Fraction(48, 17)
TOY_DEFINITION = register_kernel(
    TOY, [0.0, 0.5, 1.0],
    [[1, 0, Fraction(-120, 17), Fraction(128, 17)], [_C * c for c in (1, -4, 6, -4, 1)]],
    eta=2.6, replace=True)


def test_toy_kernel_is_registered_normalised_and_smooth():
    assert TOY in KERNEL_NAMES
    kernel = get_kernel(TOY, 2)
    total, _ = quad(lambda r: kernel.w(r, 0.7) * 2 * math.pi * r, 0, 0.7, points=[0.35], epsabs=1e-13)
    assert total == pytest.approx(1.0, abs=1e-12)
    # C2 across the break q = 1/2 and at the support edge (f, f', f'' continuous), f'(0) = 0
    for order in range(3):
        below, above = kernel.profile(np.array([0.5 - 1e-12, 0.5]), order)
        assert below == pytest.approx(above, abs=1e-9)
        assert kernel.profile(np.array([1.0 - 1e-12]), order)[0] == pytest.approx(0.0, abs=1e-9)
    assert kernel.profile(np.array([0.0]), 1)[0] == pytest.approx(0.0, abs=1e-12)


def _definition_derivatives(name, dim, q):
    """(5, len(q)) array of f, f', ..., f'''' from the definition's pieces in powers of q (not the u form)."""
    definition = get_kernel(name, dim)  # breaks and pieces in q as registered
    breaks = list(definition.breaks[:-1])
    pieces = definition._pieces
    out = np.zeros((5, q.size))
    for s, piece in enumerate(pieces):
        mask = (q >= breaks[s]) & (q < breaks[s + 1])
        poly = np.asarray(piece, dtype=float)
        for order in range(5):
            out[order, mask] = P.polyval(q[mask], poly)
            poly = P.polyder(poly) if poly.size > 1 else np.zeros(1)
    return out


@pytest.mark.parametrize("dim", [1, 2, 3])
def test_closed_forms_of_every_registered_kernel_equal_its_polynomials(dim):
    for name in KERNEL_NAMES:
        kernel = get_kernel(name, dim)
        breaks = kernel.breaks[1:-1]
        q = np.concatenate([np.linspace(0.0, 1.05, 211), [1 - 1e-3, 1 - 1e-6, 1 - 1e-12, 1.0, 2.0], breaks,
                            breaks - 1e-12, breaks + 1e-12])
        forms = kernel.closed_forms()
        closed = np.array([forms["kernel_derivatives"](x) for x in q]).T
        profile = np.array([forms["kernel_profile"](x) for x in q]).T
        reference = _definition_derivatives(name, dim, q)
        for order in range(5):
            scale = np.abs(reference[order]).max()
            np.testing.assert_allclose(closed[order], reference[order], rtol=1e-12, atol=1e-12 * scale,
                                       err_msg=f"{name} {dim}D derivative {order}")
            np.testing.assert_allclose(closed[order], kernel.profile(q, order), rtol=1e-12, atol=1e-13 * scale)
        np.testing.assert_array_equal(profile, closed[:2])
        # near the cut-off the u form keeps relative accuracy: f ~ c (1 - q)^k
        near = q[(q > 1 - 1e-3) & (q < 1)]
        np.testing.assert_allclose([forms["kernel_profile"](x)[0] for x in near], kernel.profile(near), rtol=1e-12)


@settings(max_examples=300, deadline=None, database=None)
@given(q=st.one_of(st.floats(0.0, 1.5), st.sampled_from([0.0, 0.5, 1.0, 1.0 - 2.0**-52, 0.5 - 2.0**-53])),
       dim=st.integers(1, 3))
def test_closed_forms_equal_the_polynomials_at_any_q(q, dim):
    """Property: at any q >= 0 (breaks, the cut-off and its neighbours included) every registered kernel's
    closed forms equal its polynomials in q (value and four derivatives)."""
    for name in KERNEL_NAMES:
        kernel = get_kernel(name, dim)
        closed = np.array(kernel.closed_forms()["kernel_derivatives"](q))
        reference = _definition_derivatives(name, dim, np.array([q]))[:, 0]
        scale = np.abs(_definition_derivatives(name, dim, np.linspace(0, 1, 101))).max(axis=1)
        np.testing.assert_allclose(closed, reference, rtol=1e-12, atol=1e-12 * scale.max())
        assert kernel.closed_forms()["kernel_profile"](q) == tuple(closed[:2])


def _jittered_square(n_side, spacing, rng, jitter=0.2):
    grid = np.stack(np.meshgrid(np.arange(n_side), np.arange(n_side), indexing="ij"), axis=-1).reshape(-1, 2)
    pos = np.zeros((n_side * n_side, 3))
    pos[:, :2] = (grid + 0.5 + rng.uniform(-jitter, jitter, grid.shape)) * spacing
    return pos


def test_fan_with_the_toy_kernel_has_fd_exact_forces_in_2d():
    rng = np.random.default_rng(3)
    dx = 0.03
    domain = Circle((0.15, 0.15), 0.13)
    atoms = Atoms(numbers=np.zeros(100, int), positions=_jittered_square(10, dx, rng), cell=[1, 1, 1],
                  pbc=[False, False, False])
    atoms.calc = FanCalculator(h=2.6 * dx, dx=dx, domain=domain, dim=2, kernel=TOY)
    forces = atoms.get_forces()
    numeric = calculate_numerical_forces(atoms, eps=1e-7, icarts=range(2))
    scale = np.abs(forces).max()
    assert scale > 0
    np.testing.assert_allclose(forces[:, :2], numeric[:, :2], atol=1e-6 * scale)
    # the toy kernel is really used: another kernel gives other forces
    atoms.calc = FanCalculator(h=2.6 * dx, dx=dx, domain=domain, dim=2, kernel="wendland_c2")
    assert np.abs(atoms.get_forces() - forces).max() > 1e-3 * scale


def test_alaric_with_the_toy_kernel_has_fd_exact_forces_in_2d():
    n_side = 9
    atoms = Atoms(numbers=np.zeros(n_side**2, int), positions=_jittered_square(n_side, 1.0 / n_side,
                                                                               np.random.default_rng(2), 0.25),
                  cell=np.eye(3), pbc=[True, True, False])

    def density(x):
        return 0.2 + np.exp(-((x - 0.5) ** 2).sum(axis=1) / (2 * 0.6**2))

    def gradient(x):
        return (-(x - 0.5) / 0.6**2) * (density(x) - 0.2)[:, None]

    calc = ALARICCalculator(target_density=density, target_gradient=gradient, dim=2, kernel=TOY, h_tol=1e-13,
                            cs2=0.7)
    atoms.calc = calc
    forces = atoms.get_forces()
    idx = np.arange(0, len(atoms), len(atoms) // 5)
    numeric = calculate_numerical_forces(atoms, eps=1e-6, iatoms=idx, icarts=[0, 1])
    scale = np.abs(forces).max()
    np.testing.assert_allclose(forces[idx][:, :2], numeric[:, :2], atol=1e-7 * scale)
    assert calc.kernel.name == TOY
    res = calc.results
    np.testing.assert_allclose(res["number_density"] * res["smoothing_lengths"] ** 2, calc.eta**2, rtol=1e-9)


def test_bad_registrations_are_named():
    with pytest.raises(ValueError, match="already registered"):
        register_kernel("wendland_c2", [0.0, 1.0], [[1, -1]])
    with pytest.raises(ValueError, match="breaks"):
        register_kernel("toy_bad", [0.0, 0.7], [[1, -1]])
    with pytest.raises(ValueError, match="pieces"):
        register_kernel("toy_bad", [0.0, 0.5, 1.0], [[1, -1]])
    with pytest.raises(ValueError, match="identifier"):
        register_kernel("toy bad", [0.0, 1.0], [[1, -1]])
    assert "toy_bad" not in KERNEL_NAMES
