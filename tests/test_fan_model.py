"""FanModel (ase_sphrelax.models.fan): volumes, pair, self and boundary terms of Fan Eq. 3.8 / 4.4."""
import math
import pickle

import numpy as np
import pytest
from ase.calculators.calculator import PropertyNotImplementedError

from ase_sphrelax.calculators.base import periodic_measure
from ase_sphrelax.domains import Box, Circle, Polygon, Sphere
from ase_sphrelax.kernels import get_kernel
from ase_sphrelax.models.fan import FanModel, verlet_skin


def test_volumes_follow_one_rule():
    """V: domain volume, else periodic measure, else N dx^d; v0 = dx^d, or V/N without dx (Eq. 3.2, 3.3)."""
    circle = Circle((0.0, 0.0), 2.0)
    assert FanModel(1.0, 0.5, circle).volumes(40) == (pytest.approx(4 * math.pi), 0.25, None)
    assert FanModel(1.0, None, circle).volumes(40) == (pytest.approx(4 * math.pi), pytest.approx(math.pi / 10), None)
    # the domain wins over a periodic cell; v0 = V/N still uses the domain
    assert FanModel(1.0, None, circle).volumes(40, measure=9.0).volume == pytest.approx(4 * math.pi)
    assert FanModel(1.0, None).volumes(36, measure=9.0) == (9.0, 0.25, 9.0)
    assert FanModel(1.0, 0.5).volumes(36, measure=9.0) == (9.0, 0.25, 9.0)
    assert FanModel(1.0, 0.5, dim=3).volumes(10) == (pytest.approx(1.25), 0.125, None)
    with pytest.raises(ValueError, match="dx=None needs a domain or a cell periodic"):
        FanModel(1.0, None).volumes(10)
    with pytest.raises(ValueError, match="at least one particle"):
        FanModel(1.0, 0.5).volumes(0)


def test_periodic_measure_of_a_rotated_skewed_sheet():
    """The measure is the area spanned by a, b (Gram determinant), whatever their orientation."""
    cell = np.array([[3.0, 0.0, 0.0], [1.0, 2.0, 0.0], [0.0, 0.0, 1.0]])
    angle = np.radians(33.0)
    rot = np.array([[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0], [0, 0, 1]])
    measure = periodic_measure(cell @ rot.T, (True, True, False), 2)
    assert measure == pytest.approx(6.0, rel=1e-14)
    assert FanModel(1.0).volumes(24, measure).v0 == pytest.approx(0.25, rel=1e-14)
    assert periodic_measure(cell, (True, False, False), 2) is None


@pytest.mark.parametrize("dim", [1, 2, 3])
def test_pair_self_terms_are_kernel_values(dim):
    """phi(r) = 2 v0 vt W(r, h) = C f(r/h), phi' by central differences; self term N v0 vt W(0) - V."""
    model = FanModel(2.6, 0.9, dim=dim)
    kernel = get_kernel("wendland_c2", dim)
    v0 = 0.9**dim
    r = np.linspace(0.05, 2.7, 40)
    phi, dphi = model.pair_energy(r, v0)
    np.testing.assert_allclose(phi, 2 * v0 * v0 * kernel.w(r, 2.6), rtol=1e-14)
    np.testing.assert_allclose(phi, model.pair_prefactor(v0) * kernel.profile(r / 2.6), rtol=1e-14)
    eps = 1e-6
    numeric = (model.pair_energy(r + eps, v0)[0] - model.pair_energy(r - eps, v0)[0]) / (2 * eps)
    np.testing.assert_allclose(dphi, numeric, atol=1e-8 * np.abs(dphi).max())
    assert model.self_energy(7, v0, 5.0) == pytest.approx(7 * v0 * v0 * kernel.w0(2.6) - 5.0, rel=1e-15)


@pytest.mark.parametrize("domain", [
    Circle((0.0, 0.0), 1.0),
    Polygon([[(0, 0), (1, 0), (1, 1), (0.5, 0.3), (0, 1)]]),  # non-convex, sharp corner
    Sphere((0.0, 0.0, 0.0), 1.0),
], ids=["circle", "polygon", "sphere"])
def test_boundary_force_is_minus_the_gradient_of_the_boundary_energy(domain):
    """Eq. 4.4's last term is -grad of Eq. 3.8's last term, inside, in the layer and outside."""
    dim = domain.dim
    lo, hi = domain.bounds
    h, v0 = 0.15 * (hi - lo).min(), 0.1**dim
    model = FanModel(h, 0.1, domain, dim, boundary_term="level_set")
    rng = np.random.default_rng(3)
    r_pc = np.zeros((60, 3))
    r_pc[:, :dim] = rng.uniform(lo - 0.3, hi + 0.3, (60, dim))
    phi_p = domain.phi(r_pc)
    assert (phi_p > 0).sum() > 5 and ((phi_p < 0) & (phi_p > -h)).sum() > 5 and (phi_p < -h).sum() > 0
    e_p, f_pc = model.boundary(r_pc, v0)
    kernel = get_kernel("wendland_c2", dim)
    np.testing.assert_allclose(e_p, 2 * v0 * kernel.w1_tail_integral(-phi_p, h), rtol=1e-14)
    assert np.all(f_pc[phi_p < -h] == 0.0)  # support inside: no boundary force
    eps = 1e-7
    numeric = np.zeros_like(f_pc)
    for c in range(dim):
        step = np.zeros(3)
        step[c] = eps
        numeric[:, c] = -(model.boundary(r_pc + step, v0)[0] - model.boundary(r_pc - step, v0)[0]) / (2 * eps)
    away = np.abs(phi_p) > 1e-4  # the one-sided kink of max(-phi, 0) at phi = 0
    np.testing.assert_allclose(f_pc[away], numeric[away], atol=1e-6 * np.abs(f_pc).max())
    assert model.boundary(r_pc, v0, want_forces=False)[1] is None


@pytest.mark.parametrize("domain,term", [(Sphere((0.0, 0.0, 0.0), 1.0), "level_set"),
                                         (Box((0.0, 0.0), (1.0, 1.0)), "gamma")], ids=["sphere", "box-gamma"])
def test_boundary_added_into_given_arrays_in_chunks_is_the_same_term(monkeypatch, domain, term):
    """``out=``: the term is added in place (the calculator's energies and forces), bit for bit the
    sum of the fresh arrays; the level set taken in chunks of 7 particles, or of candidates far from the wall too,
    changes no bit."""
    import ase_sphrelax.models.fan as fan

    dim = domain.dim
    lo, hi = domain.bounds
    model = FanModel(0.15 * (hi - lo).min(), 0.1, domain, dim, boundary_term=term)
    rng = np.random.default_rng(5)
    r_pc = np.zeros((50, 3))
    r_pc[:, :dim] = rng.uniform(lo - 0.2, hi + 0.2, (50, dim))
    e_p, f_pc = model.boundary(r_pc, 0.01)
    assert np.count_nonzero(e_p) > 10 and np.count_nonzero(e_p) < 50  # near and far particles
    base_e, base_f = rng.normal(size=50), rng.normal(size=(50, 3))
    out_e, out_f = base_e.copy(), base_f.copy()
    assert all(x is y for x, y in zip(model.boundary(r_pc, 0.01, out=(out_e, out_f)), (out_e, out_f)))
    np.testing.assert_array_equal(out_e, base_e + e_p)
    np.testing.assert_array_equal(out_f, base_f + f_pc)
    monkeypatch.setattr(fan, "_BOUNDARY_CHUNK", 7)
    chunked_e, chunked_f = model.boundary(r_pc, 0.01)
    np.testing.assert_array_equal(chunked_e, e_p)
    np.testing.assert_array_equal(chunked_f, f_pc)
    if term == "level_set":  # every particle a candidate, those beyond h from the wall included: they add nothing
        every_e, every_f = model.boundary(r_pc, 0.01, candidates=np.arange(50))
        np.testing.assert_array_equal(every_e, e_p)
        np.testing.assert_array_equal(every_f, f_pc)
    out_e = base_e.copy()
    assert model.boundary(r_pc, 0.01, want_forces=False, out=(out_e, None))[1] is None
    np.testing.assert_array_equal(out_e, base_e + e_p)


def test_no_domain_gives_no_boundary_term():
    e_p, f_pc = FanModel(1.0, 1.0).boundary(np.zeros((4, 3)), 1.0)
    assert np.all(e_p == 0.0) and np.all(f_pc == 0.0) and f_pc.shape == (4, 3)


def test_stress_is_refused_where_it_is_undefined():
    model = FanModel(1.0, 1.0)
    with pytest.raises(PropertyNotImplementedError, match="periodic"):
        model.check_stress(model.volumes(4), 8.0)
    with pytest.raises(PropertyNotImplementedError, match="periodic"):
        FanModel(1.0, 1.0, Box((0, 0), (1, 1))).check_stress(model.volumes(4, 4.0), 4.0)
    with pytest.raises(PropertyNotImplementedError, match="non-zero volume"):
        model.check_stress(model.volumes(4, 4.0), 0.0)


@pytest.mark.parametrize("kwargs, error, match", [
    (dict(h=0.0), ValueError, "h must be a positive finite number"),
    (dict(h=float("inf")), ValueError, "h must be"),
    (dict(h="2.6"), TypeError, "h must be a positive finite number"),
    (dict(h=1.0, dx=-1.0), ValueError, "dx must be"),
    (dict(h=1.0, dim=4), ValueError, "dim must be 1, 2 or 3"),
    (dict(h=1.0, kernel="gauss"), ValueError, "kernel must be one of"),
    (dict(h=1.0, domain=object()), TypeError, "domain must be a Domain with phi_and_normal"),
    (dict(h=1.0, dim=3, domain=Circle((0, 0), 1.0)), ValueError, "domain is 2D but dim=3"),
])
def test_bad_parameters_are_rejected_by_name(kwargs, error, match):
    with pytest.raises(error, match=match):
        FanModel(**kwargs)


def test_degenerate_domain_volume_is_an_error():
    class Empty(Circle):
        @property
        def volume(self):
            return 0.0

    with pytest.raises(ValueError, match="domain.volume must be a positive"):
        FanModel(1.0, None, Empty((0, 0), 1.0)).volumes(3)


def test_skin_default_and_check():
    assert verlet_skin(None, 2.0) == pytest.approx(0.2)
    assert verlet_skin(0, 2.0) == 0.0
    with pytest.raises(ValueError, match="skin must be"):
        verlet_skin(-0.1, 2.0)


def test_model_pickles_for_mpi_workers():
    """The relaxation deck hands the model to `mpiexec` ranks by pickle."""
    model = FanModel(0.3, 0.1, Circle((0.0, 0.0), 1.0))
    back = pickle.loads(pickle.dumps(model))
    r_pc = np.array([[0.95, 0.0, 0.0], [0.0, 1.05, 0.0]])
    np.testing.assert_array_equal(back.boundary(r_pc, 0.01)[1], model.boundary(r_pc, 0.01)[1])
    assert repr(back) == repr(model)
