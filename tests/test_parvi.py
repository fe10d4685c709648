"""SPH-ParVI: calculator forces (FD), the stationary-density theory, the default sampler, bad input, hard cases."""
import numpy as np
import pytest
from ase import Atoms
from ase.calculators.calculator import PropertyNotImplementedError
from ase.calculators.fd import calculate_numerical_forces

import ase_sphrelax
from ase_sphrelax import ParVICalculator
from ase_sphrelax.sampling import CLASSIC, get_target, metrics
from ase_sphrelax.sampling.sampler import ParVIDivergence, ParVISampler
from ase_sphrelax.sampling.targets import gaussian_target
from ase_sphrelax.sampling.theory import predicted_gaussian_moments


def _atoms(dim, n, seed=0, scale=1.0):
    pos = np.zeros((n, 3))
    pos[:, :dim] = scale * np.random.default_rng(seed).normal(size=(n, dim))
    return Atoms(f"H{n}", positions=pos, pbc=False)


def kurtosis(x):
    x = x - x.mean(axis=0)
    return float(np.mean((x**4).mean(axis=0) / (x**2).mean(axis=0) ** 2))


# -- calculator ------------------------------------------------------------------------------
@pytest.mark.parametrize("dim", [1, 2, 3])
@pytest.mark.parametrize("h", ["adaptive", 1.2])
@pytest.mark.parametrize("eos", ["isothermal", "tait"])
def test_forces_are_minus_the_energy_gradient(dim, h, eos):
    target = gaussian_target(np.zeros(dim), np.diag(np.linspace(0.5, 1.5, dim)))
    atoms = _atoms(dim, 60, seed=dim)
    calc = ParVICalculator(log_density=target.log_density, score=target.score, dim=dim, h=h, eos=eos, rho0=0.1,
                           alpha=1.3)
    calc.model.h_tol = 1e-13  # the adaptive H solve to round-off, so that FD sees the exact constraint
    atoms.calc = calc
    assert calc.conservative
    forces = atoms.get_forces()
    numeric = calculate_numerical_forces(atoms, eps=1e-5, icarts=list(range(dim)))
    np.testing.assert_allclose(forces[:, :dim], numeric[:, :dim], rtol=1e-5, atol=1e-7 * max(1.0, np.abs(forces).max()))
    assert np.all(forces[:, dim:] == 0.0)
    assert atoms.get_potential_energy() == calc.results["free_energy"]


def test_score_by_finite_differences_is_counted():
    target = get_target("gaussian")
    atoms = _atoms(2, 50)
    exact = ParVICalculator(log_density=target.log_density, score=target.score, h=1.0)
    fd = ParVICalculator(log_density=target.log_density, h=1.0)
    f_exact = exact.get_forces(atoms.copy())
    f_fd = fd.get_forces(atoms.copy())
    np.testing.assert_allclose(f_fd, f_exact, atol=1e-8)
    assert fd.evaluations == (4 * 50, 0)  # 2 d density evaluations per particle, no score
    assert exact.evaluations == (0, 50)


def test_non_conservative_formulations_have_no_energy():
    target = get_target("gaussian")
    for kwargs in (dict(formulation="pressure-log"), dict(formulation="pressure-inverse"), dict(regularisation=0.1)):
        atoms = _atoms(2, 40)
        atoms.calc = ParVICalculator(log_density=target.log_density, score=target.score, h=1.0, **kwargs)
        assert not atoms.calc.conservative
        assert np.all(np.isfinite(atoms.get_forces()))
        with pytest.raises(PropertyNotImplementedError, match="not a gradient system"):
            atoms.get_potential_energy()
    atoms = _atoms(2, 40)
    atoms.calc = ParVICalculator(score=target.score, h=1.0)
    with pytest.raises(PropertyNotImplementedError, match="log_density"):
        atoms.get_potential_energy()


def test_viscosity_uses_the_momenta_and_conserves_momentum():
    target = get_target("gaussian")
    for viscosity in ("linear", "laplacian"):
        atoms = _atoms(2, 80)
        atoms.calc = ParVICalculator(score=target.score, h=1.0, viscosity=viscosity, viscosity_alpha=0.5, nu=0.5)
        f0 = atoms.get_forces().copy()
        v = np.zeros((80, 3))
        v[:, :2] = np.random.default_rng(1).normal(size=(80, 2))
        atoms.set_velocities(v)
        f1 = atoms.get_forces()
        delta = f1 - f0
        assert np.abs(delta).max() > 1e-4  # recomputed for the new momenta
        np.testing.assert_allclose(delta.sum(axis=0), 0.0, atol=1e-12)  # pairwise antisymmetric
        power = np.einsum("pc,pc->", delta, v)
        assert power < 0  # dissipative


@pytest.mark.parametrize("viscosity", ["linear", "laplacian"])
def test_an_evaluation_keeps_no_per_particle_copies_it_does_not_need(viscosity):
    """Memory (issue 33): after an evaluation the neighbour list holds no gathered pair-sum inputs, the isothermal
    sound speed is one number seen M times (a view), the padded positions are one buffer reused by the next
    evaluation; the viscous and regularisation forces (the mass a parameter of the pair functions, the velocities
    (M, d)) are those of the per-particle sums written out here for the linear viscosity (Eq. 6)."""
    from ase_sphrelax.models.parvi import CountingTarget, ParVIModel

    target = gaussian_target(np.zeros(2), np.eye(2))
    rng = np.random.default_rng(3)
    r_pc, v_pc = rng.standard_normal((300, 2)), rng.standard_normal((300, 2))
    model = ParVIModel(CountingTarget(target.log_density, target.score, 2), 2, viscosity=viscosity,
                       viscosity_alpha=0.3, nu=0.2, regularisation=0.05)
    ev = model.evaluate(r_pc, v_pc)
    assert model.nlist.points._gather_buffers == {}
    assert not model.nlist.stored  # the first solve, from the guess: bins only, no list of the guess's pairs
    assert ev.sound_speed_p.shape == (300,) and ev.sound_speed_p.strides == (0,)
    np.testing.assert_array_equal(ev.sound_speed_p, np.full(300, model.c0))
    buffer = model._x_pc
    model.evaluate(r_pc + 0.01, v_pc)
    assert model._x_pc is buffer and model.nlist.stored  # from the last H: a Verlet list
    np.testing.assert_array_equal(buffer[:, :2], r_pc + 0.01)
    assert np.all(buffer[:, 2] == 0.0)
    # the viscous part alone, against the brute-force pair sum (Eq. 6 / Eq. 5b with the Brookshaw Laplacian)
    ev = model.evaluate(r_pc, v_pc)
    no_viscosity = model.evaluate(r_pc, None).forces  # pressure, score and regularisation only
    k = model.kernel
    m, h, rho = ev.mass, ev.h, ev.rho
    brute = np.zeros((300, 2))
    for a in range(300):
        d_bc = r_pc - r_pc[a]  # x_b - x_a
        dist = np.sqrt(np.einsum("bc,bc->b", d_bc, d_bc))
        hab = 0.5 * (h[a] + h)
        near = (dist > 0) & (dist < hab)
        slope = k.dw(dist[near], hab[near])  # dW/dr at the mean support
        if viscosity == "linear":
            vr = -np.einsum("bc,bc->b", v_pc[a] - v_pc[near], d_bc[near])  # v_ab . r_ab
            coeff = -m * m * 2.0 * 0.3 * model.c0 * hab[near] / (rho[a] + rho[near]) * vr / (
                dist[near] ** 2 + 0.01 * hab[near] ** 2) * slope / dist[near]
            brute[a] = np.sum(np.where(vr < 0, coeff, 0.0)[:, None] * d_bc[near], axis=0)
        else:
            coeff = -0.2 * m * m * 4.0 / (rho[a] + rho[near]) * slope * dist[near] / (
                dist[near] ** 2 + 0.01 * hab[near] ** 2)
            brute[a] = np.sum(coeff[:, None] * (v_pc[near] - v_pc[a]), axis=0)
    np.testing.assert_allclose(ev.forces - no_viscosity, brute, rtol=1e-9, atol=1e-12 * np.abs(brute).max())


def test_calculator_rejects_bad_atoms_and_parameters():
    target = get_target("gaussian")
    atoms = _atoms(2, 10)
    atoms.positions[3, 2] = 0.1
    with pytest.raises(ValueError, match="beyond axis 1"):
        ParVICalculator(score=target.score, dim=2).get_forces(atoms)  # dim=None would infer 3D
    with pytest.raises(ValueError, match="open space"):
        ParVICalculator(score=target.score).get_forces(Atoms("H4", positions=np.zeros((4, 3)), cell=np.eye(3) * 4,
                                                               pbc=[True, True, False]))
    with pytest.raises(ValueError, match="formulation"):
        ParVICalculator(score=target.score, formulation="nope")
    with pytest.raises(ValueError, match="alpha"):
        ParVICalculator(score=target.score, alpha=0.0)
    with pytest.raises(ValueError, match="needs log_density"):
        ParVICalculator(score=target.score, formulation="pressure-log")
    with pytest.raises(TypeError, match="unknown parameter"):
        ParVICalculator(score=target.score, hh=1)


# -- the stationary state (item 4) -------------------------------------------------------------
@pytest.mark.parametrize("dim, n", [(1, 300), (2, 500)])
@pytest.mark.parametrize("alpha", [1.0, 2.0])
def test_isothermal_score_force_gives_p_to_the_alpha_over_c0_squared(dim, n, alpha):
    """rho ~ p^(alpha/c0^2): unit Gaussian -> variance c0^2/alpha (1 and 0.5), kurtosis 3."""
    target = gaussian_target(np.zeros(dim), np.eye(dim))
    res = ParVISampler(target.log_density, target.score, dim=dim, n=n, alpha=alpha, c0=1.0,
                       seed=1, **dict(CLASSIC, steps=3000 if dim == 1 else 1200)).run()
    predicted = predicted_gaussian_moments("force", "isothermal", dim, alpha=alpha, c0=1.0)
    assert predicted["variance"] == pytest.approx(1.0 / alpha)
    assert res.samples.var(axis=0).mean() == pytest.approx(predicted["variance"], rel=0.1)
    assert kurtosis(res.samples) == pytest.approx(3.0, rel=0.15)


@pytest.mark.slow
@pytest.mark.parametrize("dim, n, h, rho0", [(1, 300, 0.05, 1.0), (2, 500, 0.25, 0.5)])
def test_tait_score_force_gives_the_compact_profile(dim, n, h, rho0):
    """Tait gamma = 7: rho = rho0 [C + 6 alpha log p / c0^2]^(1/6) with the free surface at rho0."""
    target = gaussian_target(np.zeros(dim), np.eye(dim))
    res = ParVISampler(target.log_density, target.score, dim=dim, n=n, eos="tait", rho0=rho0, h=h, courant=0.5,
                       seed=1, **dict(CLASSIC, friction=2.0, steps=6000)).run()
    predicted = predicted_gaussian_moments("force", "tait", dim, alpha=1.0, c0=1.0, rho0=rho0)
    assert predicted["variance"] < 0.3  # far from the target's 1: a weakly compressible blob
    assert res.samples.var(axis=0).mean() == pytest.approx(predicted["variance"], rel=0.1)
    assert kurtosis(res.samples) == pytest.approx(predicted["kurtosis"], rel=0.1)


def test_predicted_profiles_are_normalised_and_ordered():
    for formulation, eos in (("force", "tait"), ("pressure-log", "isothermal"), ("pressure-inverse", "isothermal"),
                             ("pressure-log", "tait")):
        for dim in (1, 2):
            moments = predicted_gaussian_moments(formulation, eos, dim, rho0=0.5)
            assert 0 < moments["variance"] < 1.0  # compact profiles are narrower than the Gaussian
            assert moments["kurtosis"] < 3.0  # and lighter-tailed
    # the pressure-log isothermal profile is the inverted paraboloid: 1D kurtosis 15/7
    assert predicted_gaussian_moments("pressure-log", "isothermal", 1)["kurtosis"] == pytest.approx(15 / 7, rel=1e-3)


# -- the default sampler ---------------------------------------------------------------------
def test_default_configuration_samples_a_2d_gaussian_within_twice_iid():
    """Done-criterion: energy distance of ase_sphrelax.sample within 2x that of i.i.d. samples."""
    target = get_target("gaussian")
    res = ase_sphrelax.sample(log_density=target.log_density, score=target.score, n=500, dim=2, seed=3)
    assert res.samples.shape == (500, 2)
    reference = target.sample(20000, np.random.default_rng(100))
    ours = metrics.energy_distance(res.samples, reference)
    iid = np.mean([metrics.energy_distance(target.sample(500, np.random.default_rng(s)), reference) for s in range(5)])
    assert ours < 2.0 * iid
    assert res.info["chosen_step"] == res.info["steps"]
    assert 500 * 1001 <= res.n_score < 500 * 1002  # the default's budget: 1000 evaluations per particle (and the start)
    for column in ("step", "mean_density", "kinetic", "energy", "n_density", "n_score", "wall"):
        assert len(res.trace[column]) == len(res.trace["step"])


def test_deterministic_for_a_seed_and_optimal_rule():
    target = get_target("correlated")
    kwargs = dict(CLASSIC, log_density=target.log_density, score=target.score, n=120, dim=2, steps=60)
    a = ase_sphrelax.sample(seed=5, **kwargs)
    b = ase_sphrelax.sample(seed=5, **kwargs)
    np.testing.assert_array_equal(a.samples, b.samples)
    c = ase_sphrelax.sample(seed=5, rule="optimal", **kwargs)
    k = int(np.argmax(c.trace["mean_density"]))
    assert c.info["chosen_step"] == c.trace["step"][k]
    np.testing.assert_array_equal(c.samples, a.alternatives["optimal"])  # the same run, the other rule
    np.testing.assert_array_equal(a.samples, c.alternatives["final"])


def test_annealed_h_and_continuity_density_run():
    target = get_target("gaussian")
    res = ParVISampler(target.log_density, target.score, n=200, h=1.0, h_schedule="anneal", h_end=0.4, seed=1,
                       **dict(CLASSIC, steps=200)).run()
    assert res.info["final_h_median"] == pytest.approx(0.4)
    assert 0.5 < res.samples.var(axis=0).mean() < 1.5
    res = ParVISampler(target.log_density, target.score, n=200, h=0.6, density="continuity", seed=1,
                       **dict(CLASSIC, steps=100)).run()
    assert np.all(np.isfinite(res.samples))


def test_any_dimension_with_the_tree():
    target = gaussian_target(np.zeros(5), np.eye(5))
    res = ParVISampler(target.log_density, target.score, dim=5, n=400, seed=2, **dict(CLASSIC, steps=300)).run()
    assert res.samples.shape == (400, 5)
    assert 0.6 < res.samples.var(axis=0).mean() < 1.2


# -- bad input and hard cases ----------------------------------------------------------------
def test_bad_input_is_named_before_work():
    target = get_target("gaussian")
    with pytest.raises(ValueError, match="dim"):
        ParVISampler(score=target.score, dim=0)
    with pytest.raises(ValueError, match="n must be"):
        ParVISampler(score=target.score, n=1)
    with pytest.raises(ValueError, match="alpha"):
        ParVISampler(score=target.score, alpha=-1.0)
    with pytest.raises(ValueError, match="give at least one"):
        ParVISampler()
    with pytest.raises(ValueError, match="score must return shape"):
        ParVISampler(score=lambda x: x[:, :1], n=40, steps=1).run()
    with pytest.raises(ValueError, match="score returned NaN"):
        ParVISampler(score=lambda x: np.full_like(x, np.nan), n=40, steps=1).run()
    with pytest.raises(ValueError, match="log_density returned NaN"):
        ParVISampler(log_density=lambda x: np.full(len(x), np.nan), n=40, steps=1).run()
    with pytest.raises(ValueError, match="x0 must have shape"):
        ParVISampler(score=target.score, n=40, x0=np.zeros((39, 2)))
    with pytest.raises(ValueError, match="use at least 17 particles"):
        ParVISampler(score=target.score, n=10, steps=1).run()  # 2D adaptive h needs > 8.4 neighbours
    with pytest.raises(ValueError, match="10-D with 500 particles"):
        ParVISampler(score=gaussian_target(np.zeros(10), np.eye(10)).score, dim=10, n=500, steps=1).run()


def test_a_diverging_time_step_is_reported_with_the_step():
    target = get_target("gaussian")
    with pytest.raises(ParVIDivergence, match="diverged at step"):
        ParVISampler(target.log_density, target.score, n=100, h=0.5, dt=5.0, **dict(CLASSIC, steps=50, friction=0.0)).run()


def test_zero_density_far_away_keeps_particles_finite():
    """log p = -inf outside |x| < 3 (a truncated Gaussian): pressure and FD-score runs stay finite."""
    def log_density(x):
        lp = -0.5 * np.einsum("pc,pc->p", x, x)
        return np.where(np.linalg.norm(x, axis=1) < 3.0, lp, -np.inf)

    x0 = np.random.default_rng(0).normal(size=(150, 2)) * 2.5
    for formulation in ("force", "pressure-log"):
        res = ParVISampler(log_density=log_density, n=150, formulation=formulation, x0=x0, seed=0,
                           **dict(CLASSIC, steps=80)).run()
        assert np.all(np.isfinite(res.samples))
    # 1/(alpha (p + eps)) is 1/(alpha eps) where p = 0: a pressure jump no step resolves; reported, never NaN
    with pytest.raises(ParVIDivergence, match="diverged at step"):
        ParVISampler(log_density=log_density, n=150, formulation="pressure-inverse", x0=x0,
                     **dict(CLASSIC, steps=80)).run()
    res = ParVISampler(log_density=log_density, n=150, x0=x0, seed=0, **dict(CLASSIC, steps=300)).run()
    assert res.info["fallback"] > 0  # particles outside were pulled back
    assert np.mean(np.linalg.norm(res.samples, axis=1) < 3.0) > 0.95


def test_adaptive_h_from_a_start_with_the_first_neighbour_just_outside():
    """The H solve of ase_sphrelax.sph from a guess whose first neighbour sits at q = 1 - 1e-3: the Newton
    slope is ~0 there and an unlimited step overshot the growth cap (fixed: steps beyond 2x are doubled)."""
    from ase_sphrelax import sph
    from ase_sphrelax.kernels import get_kernel
    from ase_sphrelax.neighbors import NeighborList

    rng = np.random.default_rng(0)
    x = np.zeros((201, 3))
    x[:200, :2] = 0.3 * rng.normal(size=(200, 2))
    x[200, :2] = [3.0, 0.0]
    h0 = np.full(201, 0.3)
    h0[200] = 1.001 * np.linalg.norm(x[:200] - x[200], axis=1).min()
    eta = np.sqrt(32 / np.pi)
    sums = sph.solve_smoothing_lengths(NeighborList(0.3, skin=0.05), x, np.zeros((3, 3)), np.zeros(3, bool),
                                       1 / 201, get_kernel("wendland_c2", 2), eta=eta, h0=h0)
    np.testing.assert_allclose(sums.rho_p * sums.h_p**2 * 201, eta**2, rtol=1e-6)


def test_all_particles_in_one_point():
    """Coincident starts are moved apart by a seeded 1e-3 jitter; the default then spreads to the target."""
    target = get_target("gaussian")
    res = ParVISampler(target.log_density, target.score, n=200, x0=np.zeros((200, 2)), seed=4, **CLASSIC).run()
    assert res.info["jittered"] == 199
    assert res.samples.var(axis=0).mean() == pytest.approx(1.0, rel=0.1)
    again = ParVISampler(target.log_density, target.score, n=200, x0=np.zeros((200, 2)), seed=4,
                         **dict(CLASSIC, steps=5)).run()
    np.testing.assert_array_equal(again.trace["mean_density"][:1], res.trace["mean_density"][:1])  # deterministic


def test_a_mode_far_from_the_proposal_is_reached():
    target = gaussian_target(np.array([8.0, -6.0]), np.eye(2))
    res = ParVISampler(target.log_density, target.score, n=200, seed=1, **dict(CLASSIC, steps=1500)).run()
    assert metrics.mean_error(res.samples, target.mean) < 0.2
