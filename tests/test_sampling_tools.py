"""Targets, metrics and baselines of the sampling evaluation (brute force, scipy, POT, blackjax, analytic)."""
import numpy as np
import pytest
from scipy import stats

from ase_sphrelax.sampling import TARGET_NAMES, get_target
from ase_sphrelax.sampling import baselines, metrics


# -- targets ---------------------------------------------------------------------------------
@pytest.mark.parametrize("name", TARGET_NAMES)
def test_score_is_the_gradient_of_the_log_density(name):
    if name == "logistic":
        pytest.importorskip("sklearn")
    target = get_target(name)
    rng = np.random.default_rng(0)
    x = target.sample(40, rng) if target.sample else 0.3 * rng.standard_normal((40, target.dim))
    eps = 1e-6
    fd = np.empty_like(x)
    for c in range(target.dim):
        e = np.zeros(target.dim)
        e[c] = eps
        fd[:, c] = (target.log_density(x + e) - target.log_density(x - e)) / (2 * eps)
    np.testing.assert_allclose(target.score(x), fd, rtol=1e-5, atol=1e-5 * max(1.0, np.abs(fd).max()))


@pytest.mark.parametrize("name", ["gaussian", "correlated", "ring8", "banana", "donut", "gaussian10d"])
def test_iid_samplers_have_the_exact_moments(name):
    target = get_target(name)
    x = target.sample(200000, np.random.default_rng(1))
    assert metrics.cov_error(x, target.cov) < 0.02
    assert metrics.mean_error(x, target.mean) < 0.05 * np.sqrt(np.trace(target.cov))


def test_iid_samplers_follow_their_densities():
    """A 2D histogram of the i.i.d. samples against the normalised density on a grid."""
    rng = np.random.default_rng(2)
    for name, box in (("donut", 3.5), ("ring8", 4.0), ("funnel", 3.0)):
        target = get_target(name)
        x = target.sample(400000, rng)
        edges = np.linspace(-box, box, 41)
        hist, _, _ = np.histogram2d(x[:, 0], x[:, 1], bins=[edges, edges])
        mid = 0.5 * (edges[1:] + edges[:-1])
        gx, gy = np.meshgrid(mid, mid, indexing="ij")
        fine = np.linspace(-12, 12, 1201)
        fx, fy = np.meshgrid(fine, fine, indexing="ij")
        z = np.exp(target.log_density(np.stack([fx.ravel(), fy.ravel()], 1))).sum() * (fine[1] - fine[0]) ** 2
        if name == "funnel":  # the funnel's mass reaches beyond the grid along x1: normalise on exp(x0/2)
            z = np.sqrt(2 * np.pi) * np.sqrt(2 * np.pi * 9)  # exact: int exp(log p) = 2 pi * 3
        p = np.exp(target.log_density(np.stack([gx.ravel(), gy.ravel()], 1))).reshape(gx.shape) / z
        expected = p * (edges[1] - edges[0]) ** 2 * len(x)
        big = expected > 500
        assert big.sum() > 20
        np.testing.assert_allclose(hist[big], expected[big], rtol=0.12)


def test_logistic_target_has_32_parameters_and_a_sane_mode():
    pytest.importorskip("sklearn")
    target = get_target("logistic")
    assert target.dim == 32
    from scipy.optimize import minimize

    res = minimize(lambda t: -target.log_density(t[None])[0], np.zeros(32), jac=lambda t: -target.score(t[None])[0],
                   method="L-BFGS-B")
    w = res.x[:31]
    accuracy = np.mean(np.sign(target.extra["x"] @ w) == target.extra["y"])
    assert accuracy > 0.97  # the breast-cancer set is nearly separable


def test_unknown_target_is_named():
    with pytest.raises(ValueError, match="target must be one of"):
        get_target("nope")
    with pytest.raises(ValueError, match=r"shape \(M, 2\)"):
        get_target("gaussian").log_density(np.zeros((3, 3)))


# -- metrics ---------------------------------------------------------------------------------
def test_energy_distance_against_scipy_and_brute_force():
    rng = np.random.default_rng(3)
    u, v = rng.normal(size=300), rng.normal(0.3, 1.2, size=211)
    assert metrics.energy_distance(u, v) == pytest.approx(stats.energy_distance(u, v) ** 2, rel=1e-10)
    x, y = rng.normal(size=(150, 3)), rng.normal(size=(90, 3)) + 0.2
    r = lambda a, b: np.linalg.norm(a[:, None] - b[None], axis=2).mean()  # noqa: E731
    assert metrics.energy_distance(x, y) == pytest.approx(2 * r(x, y) - r(x, x) - r(y, y), rel=1e-12)
    assert metrics.energy_distance(x, x) == pytest.approx(0.0, abs=1e-12)


def test_mmd_against_brute_force():
    rng = np.random.default_rng(4)
    x, y = rng.normal(size=(120, 2)), rng.normal(size=(80, 2)) * 1.3
    ell = metrics.median_distance(y)
    k = lambda a, b: np.exp(-0.5 * ((a[:, None] - b[None]) ** 2).sum(2) / ell**2).mean()  # noqa: E731
    assert metrics.mmd(x, y, ell) == pytest.approx(k(x, x) + k(y, y) - 2 * k(x, y), rel=1e-12)


def test_wasserstein_1d_against_scipy():
    rng = np.random.default_rng(5)
    u, v = rng.normal(size=137), rng.exponential(size=59)
    assert metrics.wasserstein_1d(u, v, p=1) == pytest.approx(stats.wasserstein_distance(u, v), rel=1e-12)


def test_sliced_wasserstein_against_pot():
    ot = pytest.importorskip("ot")
    rng = np.random.default_rng(6)
    for n, m in ((200, 200), (150, 97)):
        x, y = rng.normal(size=(n, 3)), rng.normal(size=(m, 3)) + [0.5, 0, 0]
        theta = metrics.random_directions(3, 50, seed=1)
        ours = metrics.sliced_wasserstein(x, y, directions=theta)
        theirs = ot.sliced_wasserstein_distance(x, y, projections=theta.T)
        assert ours == pytest.approx(float(theirs), rel=1e-8)


def test_mode_weights():
    target = get_target("ring8")
    x = target.sample(80000, np.random.default_rng(7))
    assert metrics.mode_weight_error(x, target.modes, target.mode_weights) < 0.01
    one_mode = target.modes[[0]] + 0.1 * np.random.default_rng(8).normal(size=(100, 2))
    assert metrics.mode_weight_error(one_mode, target.modes, target.mode_weights) == pytest.approx(7 / 8)


# -- baselines -------------------------------------------------------------------------------
def test_ula_has_its_analytic_bias():
    """ULA on N(0, 1) with step eps is stationary at variance 1 / (1 - eps / 2)."""
    x0 = np.zeros((20000, 1))
    eps = 0.5
    res = baselines.ula(lambda x: -x, x0, 200, eps, seed=1)
    assert np.var(res.samples) == pytest.approx(1 / (1 - eps / 2), rel=0.03)
    assert res.n_score == 200 * 20000


def test_mala_removes_the_bias():
    target = get_target("correlated")
    x0 = np.random.default_rng(2).normal(size=(4000, 2))
    res = baselines.mala(target.log_density, target.score, x0, 600, 0.08, seed=3)
    assert metrics.cov_error(res.samples, target.cov) < 0.05
    assert 0.5 < res.info["acceptance"] < 1.0
    assert res.n_density == res.n_score == 601 * 4000


def test_svgd_matches_blackjax():
    jax = pytest.importorskip("jax")
    pytest.importorskip("blackjax")
    import blackjax
    import jax.numpy as jnp
    import optax

    jax.config.update("jax_enable_x64", True)
    try:
        target = get_target("correlated")
        prec = np.linalg.inv(target.cov)
        x0 = np.random.default_rng(4).normal(size=(60, 2)) * 2.0
        ell0 = baselines.median_length_scale(x0)
        ours = baselines.svgd(target.score, x0, 25, lr=0.05)
        logp = lambda x: -0.5 * x @ jnp.asarray(prec) @ x  # noqa: E731
        algo = blackjax.svgd(jax.grad(logp), optax.adam(0.05))
        state = algo.init(jnp.asarray(x0), {"length_scale": ell0})
        for _ in range(25):
            state = algo.step(state)
        np.testing.assert_allclose(ours.samples, np.asarray(state.particles), rtol=1e-9, atol=1e-9)
    finally:
        jax.config.update("jax_enable_x64", False)


def test_svgd_converges_on_a_gaussian():
    target = get_target("gaussian")
    x0 = np.random.default_rng(5).normal(size=(200, 2)) * 0.3 + 1.0
    res = baselines.svgd(target.score, x0, 500, lr=0.1)
    assert metrics.mean_error(res.samples, target.mean) < 0.05
    assert metrics.cov_error(res.samples, target.cov) < 0.15


def test_emcee_samples_a_gaussian():
    pytest.importorskip("emcee")
    target = get_target("gaussian")
    x0 = np.random.default_rng(6).normal(size=(400, 2)) * 0.5
    res = baselines.emcee_ensemble(target.log_density, x0, 400, seed=1)
    assert res.samples.shape == (400, 2)
    assert metrics.cov_error(res.samples, target.cov) < 0.2
    assert res.n_density >= 400 * 400


def test_baselines_reject_bad_input():
    with pytest.raises(ValueError, match="x0 must have shape"):
        baselines.ula(lambda x: -x, np.zeros(3), 10, 0.1)
    with pytest.raises(ValueError, match="steps"):
        baselines.svgd(lambda x: -x, np.zeros((3, 2)), -1)
    with pytest.raises(ValueError, match="score must return shape"):
        baselines.ula(lambda x: -x[:, :1], np.zeros((3, 2)), 1, 0.1)
