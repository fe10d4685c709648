"""Quality metrics against Table 2, brute-force kernel sums and exact lattice geometry."""
import numpy as np
import pytest

from ase_sphrelax.analysis import Quality, quality_summary
from ase_sphrelax.build import fill, periodic_box
from ase_sphrelax.domains import Box
from ase_sphrelax.kernels import get_kernel

from conftest import random_periodic


def test_perfect_hexagonal_lattice_errors_follow_table_2():
    """Unit volume: sum_j W_ij = 1/v_c (Eq. 3.10, 5.2); by symmetry sum_j grad W_ij = 0."""
    q = quality_summary(periodic_box((10, 12), dx=1.0, lattice="hexagonal"), h=2.6, dx=1.0)
    assert q["kernel_sum_error_mean"] == pytest.approx(1 / 0.991235 - 1, abs=2e-6)
    assert q["kernel_sum_error_max"] == pytest.approx(q["kernel_sum_error_mean"], rel=1e-10)
    assert q["gradient_error_max"] < 1e-12 and q["kernel_sum_std"] < 1e-12


def test_kernel_sums_match_a_brute_force_double_sum():
    atoms = random_periodic(120, 2, np.random.default_rng(8))
    result = Quality(h=2.2, dx=1.0).compute(atoms)
    kernel = get_kernel("wendland_c2", 2)
    d_ppc = atoms.positions[None, :, :2] - atoms.positions[:, None, :2]
    length = atoms.cell[0, 0]
    d_ppc -= length * np.round(d_ppc / length)
    r_pp = np.linalg.norm(d_ppc, axis=2)
    np.testing.assert_allclose(result.kernel_sum_p, kernel.w(r_pp, 2.2).sum(axis=1), rtol=1e-12)
    grad_pc = (kernel.dw(r_pp, 2.2) / np.where(r_pp > 0, r_pp, 1.0))[:, :, None] * -d_ppc
    np.testing.assert_allclose(result.gradient_error_p, 2.2 * np.linalg.norm(grad_pc.sum(axis=1), axis=1),
                               atol=1e-12)


def test_square_lattice_in_a_box_has_its_boundary_layer_at_half_dx():
    """Cell centres of an aligned grid: the first layer sits at dx/2 (Fan Sec. 4.2, square lattice)."""
    dx = 0.05
    box = Box((0.0, 0.0), (1.0, 1.0))
    result = Quality(h=2.6 * dx, dx=dx, domain=box).compute(fill(box, dx, jitter=0.0))
    summary = result.summary()
    assert summary["n_boundary_layer"] == 4 * 20 - 4
    assert summary["boundary_distance_min"] == pytest.approx(0.5)
    assert summary["boundary_distance_max"] == pytest.approx(0.5)
    # support inside the domain: phi <= -h, i.e. at least 2.6 dx from every side
    assert summary["n_interior"] == (20 - 2 * 3) ** 2
    assert summary["n_outside"] == 0


def test_quality_rejects_bad_input():
    with pytest.raises(ValueError, match="h must be"):
        Quality(h=0.0)
    with pytest.raises(ValueError, match="dim must be"):
        Quality(h=1.0, dim=5)
    from ase import Atoms

    with pytest.raises(ValueError, match="at least one particle"):
        Quality(h=1.0, dx=1.0).compute(Atoms())


def test_particle_volume_follows_the_fan_model():
    """V_j is the calculators' v0: dx^d, or V/N from the domain or the periodic cell."""
    from ase_sphrelax import FanCalculator
    from ase_sphrelax.domains import Circle

    circle = Circle((0.0, 0.0), 1.0)
    atoms = fill(circle, 0.1, jitter=0.1, seed=3)
    for dx in (0.1, None):
        q = Quality(h=0.26, dx=dx, domain=circle).compute(atoms)
        assert q.v0 == FanCalculator(h=0.26, dx=dx, domain=circle).volumes(atoms).v0
    assert Quality(h=0.26, dx=None, domain=circle).compute(atoms).v0 == pytest.approx(np.pi / len(atoms), rel=1e-14)
    box = periodic_box((6, 6), dx=0.5)
    assert Quality(h=1.3).compute(box).v0 == pytest.approx(0.25, rel=1e-14)


@pytest.mark.parametrize("kwargs", [dict(h=-1.0), dict(h="1"), dict(h=1.0, dx=0.0), dict(h=1.0, dim=0),
                                    dict(h=1.0, kernel="gauss"), dict(h=1.0, domain=object())])
def test_quality_rejects_what_fan_calculator_rejects(kwargs):
    from ase_sphrelax import FanCalculator

    with pytest.raises(Exception) as ours:
        Quality(**kwargs)
    with pytest.raises(Exception) as calc:
        FanCalculator(**kwargs)
    assert (type(ours.value), str(ours.value)) == (type(calc.value), str(calc.value))
