"""The numpy + cKDTree reference of benchmarks/_reference.py equals FanCalculator.

The benchmark bench_fan_forces.py times FanCalculator against this reference,
so both must compute the same thing: energy (Fan Eq. 3.8), per-particle
energies and forces (Eq. 3.17 interior, Eq. 4.4 with the boundary term).
The reference itself is anchored to Fan's Table 2 (characteristic volumes of
perfect lattices at h = 2.6), independently of FanCalculator.
"""
import sys
from pathlib import Path

import numpy as np
import pytest

from ase_sphrelax import FanCalculator
from ase_sphrelax.build import fill, periodic_box
from ase_sphrelax.domains import Box, Circle

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from _reference import ReferenceFan, profile_and_slope  # noqa: E402

RTOL = 1e-12


def _compare(atoms, ref, calc):
    e_ref, ep_ref, f_ref = ref.compute(atoms)
    atoms.calc = calc
    f = atoms.get_forces()
    f_scale = np.abs(f_ref).max()
    assert f_scale > 0
    np.testing.assert_allclose(atoms.get_potential_energy(), e_ref, rtol=RTOL, atol=1e-14 * abs(ep_ref).sum())
    np.testing.assert_allclose(atoms.get_potential_energies(), ep_ref, rtol=0, atol=1e-12 * abs(ep_ref).max())
    np.testing.assert_allclose(f, f_ref, rtol=0, atol=1e-12 * f_scale)


@pytest.mark.parametrize("kernel", ["wendland_c2", "wendland_c4", "cubic_spline"])
def test_profile_matches_kernel(kernel):
    from ase_sphrelax.kernels import get_kernel
    k = get_kernel(kernel, 2)
    q = np.linspace(0, 1.2, 241)
    f, df = profile_and_slope(q, k)
    np.testing.assert_allclose(f, k.profile(q), atol=1e-14)
    np.testing.assert_allclose(df, k.profile_slope(q), atol=1e-13)


@pytest.mark.parametrize("lattice, v_c", [("square", 0.989635), ("hexagonal", 0.991235)])
def test_reference_reproduces_fan_table2(lattice, v_c):
    """Perfect lattice, unit volume, h = 2.6: E/N = sum_j W_ij - 1 = 1/v_c - 1 (Fan Table 2)."""
    atoms = periodic_box((12, 12), dx=1.0, lattice=lattice)
    energy, energies, _ = ReferenceFan(2.6).compute(atoms)
    assert abs(energy / len(atoms) - (1.0 / v_c - 1.0)) < 2e-6
    assert np.ptp(energies) < 1e-12


@pytest.mark.parametrize("kernel", ["wendland_c2", "cubic_spline"])
@pytest.mark.parametrize("dim, ratio", [(2, 2.6), (2, 1.5), (3, 2.2)])
def test_periodic_matches_fan_calculator(dim, ratio, kernel):
    n = 24 if dim == 2 else 9
    atoms = periodic_box(n, dx=1.0, dim=dim, lattice="square" if dim == 2 else "cubic", jitter=0.3, seed=3)
    _compare(atoms, ReferenceFan(ratio, dim=dim, kernel=kernel), FanCalculator(ratio, dim=dim, kernel=kernel))


def test_periodic_with_dx_matches_fan_calculator():
    atoms = periodic_box((20, 14), dx=0.5, lattice="hexagonal", jitter=0.2, seed=4)
    _compare(atoms, ReferenceFan(1.3, dx=0.5), FanCalculator(1.3, dx=0.5))


@pytest.mark.parametrize("domain", [Circle((0.5, 0.5), 0.2), Box((0.2, 0.3), (0.7, 0.6))])
def test_bounded_domain_matches_fan_calculator(domain):
    dx = 1.0 / 64
    atoms = fill(domain, dx, jitter=0.3, seed=5)
    atoms.positions[:5, :2] += 0.6 * dx  # a few particles near/outside the boundary
    _compare(atoms, ReferenceFan(2.6 * dx, dx=dx, domain=domain),  # the reference has Fan's level-set term
             FanCalculator(2.6 * dx, dx=dx, domain=domain, boundary_term="level_set"))


def test_skin_reuse_gives_the_same_result():
    """Warm evaluations (pair list reused within skin/2) equal cold ones, and the list is rebuilt when needed."""
    atoms = periodic_box(30, dx=1.0, jitter=0.25, seed=6)
    warm = ReferenceFan(2.6, skin=0.3)
    warm.compute(atoms)
    rng = np.random.default_rng(0)
    atoms.positions[:, :2] += rng.uniform(-0.1, 0.1, (len(atoms), 2))  # < skin/2 = 0.15
    e_warm, _, f_warm = warm.compute(atoms)
    assert warm.builds == 1
    e_cold, _, f_cold = ReferenceFan(2.6).compute(atoms)
    assert e_warm == pytest.approx(e_cold, rel=1e-13)
    np.testing.assert_allclose(f_warm, f_cold, atol=1e-13)
    atoms.positions[0, 0] += 0.2  # > skin/2: rebuild
    warm.compute(atoms)
    assert warm.builds == 2


def test_rejects_skewed_or_small_cells():
    atoms = periodic_box(10, dx=1.0)
    with pytest.raises(ValueError, match="exceed"):
        ReferenceFan(6.0).compute(atoms)
    atoms.set_cell([[10, 0, 0], [3, 10, 0], [0, 0, 1]])
    with pytest.raises(ValueError, match="orthogonal"):
        ReferenceFan(2.6).compute(atoms)
