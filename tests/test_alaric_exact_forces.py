"""ALARIC forces are -grad U wherever U is defined: close pairs (1e-4 H) and tight triples (0.01 H) included.

Issue 20 item 1: Omega (Eq. 13) was floored at 0.05 in the forces, so at a pair 1e-4 apart (Omega ~ 4e-3) the
force was off by 30x. Where U is not defined (coincident particles: no H solves n H^d = eta^d), the error
names the particle and says that it coincides with another.
"""
import numpy as np
import pytest
from ase import Atoms
from ase.calculators.fd import calculate_numerical_forces
from hypothesis import example, given, settings, strategies as st

from ase_sphrelax import ALARICCalculator
from ase_sphrelax.sph import SmoothingLengthError

CONSERVATIVE_FORMS = ("log", "squares")


def _target(dim):
    def density(x):
        return 1.0 + 0.5 * np.sin(2 * np.pi * x).prod(axis=1)

    def gradient(x):
        s, c = np.sin(2 * np.pi * x), np.cos(2 * np.pi * x)
        out = np.empty_like(x)
        for k in range(dim):
            others = np.prod(np.delete(s, k, axis=1), axis=1) if dim > 1 else 1.0
            out[:, k] = 0.5 * 2 * np.pi * c[:, k] * others
        return out

    return density, gradient


def _random_start_with_close_particles(dim, seed):
    """Uniformly random particles in the periodic unit cell, with a pair 1e-4 H apart and a triple within 0.01 H."""
    n = {1: 40, 2: 60, 3: 90}[dim]
    rng = np.random.default_rng(seed)
    pos = np.zeros((n, 3))
    pos[:, :dim] = rng.uniform(0.0, 1.0, (n, dim))
    h = 3.0 * n ** (-1.0 / dim)  # eta (V / N)^(1/d), eta = 3 for Wendland C4: the typical support H

    def direction():
        u = rng.normal(size=dim)
        return u / np.linalg.norm(u)

    pos[1, :dim] = pos[0, :dim] + 1e-4 * h * direction()
    for k in (3, 4):
        pos[k, :dim] = pos[2, :dim] + 0.01 * h * rng.uniform(0.2, 1.0) * direction()
    cell = np.eye(3)
    pbc = [True] * dim + [False] * (3 - dim)
    return Atoms(numbers=np.zeros(n, int), positions=pos % 1.0, cell=cell, pbc=pbc)


def _check_fd(atoms, dim, form, seed, **options):
    density, gradient = _target(dim)
    calc = ALARICCalculator(target_density=density, target_gradient=gradient, dim=dim, form=form, h_tol=1e-14,
                            **options)
    atoms.calc = calc
    f = atoms.get_forces()
    h_min = float(calc.results["smoothing_lengths"].min())
    # the close pair's own separation, by the minimum image: the start wraps positions into the cell, and a pair
    # that straddles a periodic face read about 1 apart, so the step below was 1e-3 instead of 1e-7 H (seed 1600)
    pair = float(atoms.get_distance(0, 1, mic=True))
    # the close particles, their neighbours (the pair's Omega enters their forces) and a few others
    others = np.random.default_rng(seed).choice(np.arange(5, len(atoms)), 3, replace=False)
    near = np.nonzero(atoms.get_distances(0, np.arange(len(atoms)), mic=True) < h_min)[0][:4]
    idx = np.unique(np.concatenate([np.arange(5), near, others]))
    fd = calculate_numerical_forces(atoms, eps=1e-3 * pair, iatoms=idx, icarts=list(range(dim)))
    scale = np.abs(f[idx]).max()
    np.testing.assert_allclose(f[idx][:, :dim], fd[:, :dim], rtol=0, atol=2e-5 * scale)
    return calc


@settings(max_examples=12, deadline=None, database=None)
@given(dim=st.sampled_from([1, 2, 3]), form=st.sampled_from(CONSERVATIVE_FORMS),
       seed=st.integers(min_value=0, max_value=2**31 - 1))
def test_forces_are_the_negative_gradient_at_close_pairs_and_triples(dim, form, seed):
    calc = _check_fd(_random_start_with_close_particles(dim, seed), dim, form, seed % 1000)
    assert calc.results["omega"].min() > 0.0


@settings(max_examples=8, deadline=None, database=None)
@given(dim=st.sampled_from([1, 2, 3]), background=st.sampled_from([0.01, 0.1, 1.0]),
       seed=st.integers(min_value=0, max_value=2**31 - 1))
@example(dim=2, background=0.01, seed=1600)  # the close pair straddles a periodic face (CI, 2026-12-07)
def test_squares_with_background_pressure_forces_are_the_negative_gradient(dim, background, seed):
    """form="squares" with background > 0 (energy + beta sum m c_s^2 ln rho): FD-exact at close pairs and triples."""
    calc = _check_fd(_random_start_with_close_particles(dim, seed), dim, "squares", seed % 1000,
                     background=background)
    assert calc.parameters.background == background


def _issue_start(**calc_options):
    """The issue's case: 60 uniformly random particles on the periodic [-1, 1), particles 14 and 15 1e-4 apart."""
    n = 60
    rng = np.random.default_rng(0)
    x = np.sort(rng.uniform(0.0, 2.0, n))
    x[15] = x[14] + 1e-4
    pos = np.zeros((n, 3))
    pos[:, 0] = x
    atoms = Atoms(numbers=np.zeros(n, int), positions=pos, cell=[2.0, 0.0, 0.0], pbc=[True, False, False])
    atoms.calc = ALARICCalculator(target_density=lambda y: 1 + 0.5 * np.sin(np.pi * y[:, 0]),
                                  target_gradient=lambda y: (0.5 * np.pi * np.cos(np.pi * y[:, 0]))[:, None],
                                  dim=1, origin=[-1.0], **calc_options)
    return atoms


def test_issue_reproducer_close_pair_1d():
    """60 random particles on a periodic interval, two of them 1e-4 apart (Omega ~ 4e-3): force = -dU/dx.

    With Omega floored at 0.05 in the forces this gave -0.755 against the central difference -20.8.
    """
    atoms = _issue_start(h_tol=1e-13)
    f = atoms.get_forces()
    assert atoms.calc.results["omega"][14] < 0.01
    idx = [13, 14, 15, 16]
    fd = calculate_numerical_forces(atoms, eps=1e-7, iatoms=idx, icarts=[0])
    np.testing.assert_allclose(f[idx, 0], fd[:, 0], rtol=1e-5)


@pytest.mark.parametrize("dim,k", [(1, 2), (1, 3), (2, 4), (3, 6)])
def test_coincident_particles_are_named(dim, k):
    """k coincident particles whose own kernel sum k sigma f(0) reaches eta^d: no H exists, the error says so."""
    n_side = {1: 40, 2: 8, 3: 5}[dim]
    grid = np.stack(np.meshgrid(*[np.arange(n_side)] * dim, indexing="ij"), axis=-1).reshape(-1, dim)
    pos = np.zeros((len(grid), 3))
    pos[:, :dim] = (grid + 0.5) / n_side
    pos[1:k] = pos[0]
    atoms = Atoms(numbers=np.zeros(len(pos), int), positions=pos, cell=np.eye(3),
                  pbc=[True] * dim + [False] * (3 - dim))
    calc = ALARICCalculator(target_density=lambda x: np.ones(len(x)), dim=dim)
    atoms.calc = calc
    assert k * calc.kernel.sigma * calc.kernel.f0 >= calc.eta**dim * (1 - 1e-12)
    with pytest.raises(SmoothingLengthError, match=r"particle \d+ .*coincides with particle"):
        atoms.get_forces()


def test_omega_floor_is_for_the_paper_form_only():
    density, gradient = _target(1)
    with pytest.raises(ValueError, match="omega_floor is for form='paper' only"):
        ALARICCalculator(target_density=density, dim=1, omega_floor=0.05)
    with pytest.raises(ValueError, match="omega_floor must be"):
        ALARICCalculator(target_density=density, dim=1, form="paper", omega_floor=-1.0)
    ALARICCalculator(target_density=density, dim=1, form="paper", omega_floor=0.0)


def test_dynamics_resolves_the_stiff_force_of_a_close_pair():
    """The exact force at a pair 1e-4 apart is stiff (Omega ~ 4e-3); the dynamics' force step C sqrt(H/|a|)
    shrinks for it, the pair separates and epsilon falls, with no TimeStepError."""
    from ase_sphrelax.drivers.alaric_dynamics import ALARICDynamics

    atoms = _issue_start()
    atoms.get_forces()
    eps0 = atoms.calc.results["epsilon"]
    dyn = ALARICDynamics(atoms)
    steps = []
    dyn.attach(lambda: steps.append(dyn.dt), interval=1)
    dyn.run(300)
    assert np.all(np.isfinite(atoms.positions))
    assert min(steps[:5]) < 0.2 * np.median(steps)  # the force condition acted on the close pair
    xs = np.sort(np.mod(atoms.positions[:, 0], 2.0))
    assert np.diff(np.concatenate([xs, [xs[0] + 2.0]])).min() > 100 * 1e-4
    assert atoms.calc.results["epsilon"] < 1e-2 * eps0


# -- mirror ghosts at the domain's boundary (boundary="mirror") -----------------------------------------------------
def _ball_start_with_close_particles(dim, seed):
    """Uniformly random particles in the unit disc/ball, a pair 1e-4 H apart next to the boundary (both get ghosts,
    and each sees the other's ghost) and a triple within 0.01 H."""
    n = {2: 120, 3: 260}[dim]
    rng = np.random.default_rng(seed)
    x = rng.normal(size=(n, dim))
    x *= (rng.uniform(0.0, 1.0, (n, 1)) ** (1.0 / dim)) / np.linalg.norm(x, axis=1)[:, None]
    h = 3.0 * (np.pi / n) ** (1.0 / dim)

    def direction():
        u = rng.normal(size=dim)
        return u / np.linalg.norm(u)

    x[0] *= rng.uniform(0.9, 0.99) / np.linalg.norm(x[0])
    x[1] = x[0] + 1e-4 * h * direction()
    for k in (3, 4):
        x[k] = x[2] + 0.01 * h * rng.uniform(0.2, 1.0) * direction()
    pos = np.zeros((n, 3))
    pos[:, :dim] = x
    return Atoms(numbers=np.zeros(n, int), positions=pos, pbc=False)


def _mirror_domain(dim, kind):
    from ase_sphrelax.domains import Circle, Sphere

    if dim == 3:
        return Sphere((0.0, 0.0, 0.0), 1.0)
    return Circle((0.0, 0.0), 1.0) if kind == "ball" else Circle((0.0, 0.0), 1.0).to_polygon(48)


@settings(max_examples=8, deadline=None, database=None)
@given(dim=st.sampled_from([2, 3]), kind=st.sampled_from(["ball", "polygon"]), form=st.sampled_from(CONSERVATIVE_FORMS),
       seed=st.integers(min_value=0, max_value=2**31 - 1))
def test_mirror_forces_are_the_negative_gradient(dim, kind, form, seed):
    """boundary="mirror": the ghosts' share of the force comes back through the mirror's Jacobian; FD-exact at the
    close pair (next to the boundary), the triple and the particles closest to the boundary."""
    atoms = _ball_start_with_close_particles(dim, seed)
    domain = _mirror_domain(dim, kind)
    calc = ALARICCalculator(target_density=lambda x: 1.0 + 0.3 * x[:, 0], dim=dim, form=form, domain=domain,
                            target_gradient=lambda x: np.eye(dim)[0] * 0.3 + 0 * x, boundary="mirror", h_tol=1e-14)
    atoms.calc = calc
    f = atoms.get_forces()
    assert len(calc._ghosts[0]) > 0
    radius = np.linalg.norm(atoms.positions[:, :dim], axis=1)
    idx = np.unique(np.concatenate([np.arange(5), np.argsort(-radius)[:4]]))
    # the close pair's own separation, by the minimum image: the start wraps positions into the cell, and a pair
    # that straddles a periodic face read about 1 apart, so the step below was 1e-3 instead of 1e-7 H (seed 1600)
    pair = float(atoms.get_distance(0, 1, mic=True))
    fd = calculate_numerical_forces(atoms, eps=1e-3 * pair, iatoms=idx, icarts=list(range(dim)))
    np.testing.assert_allclose(f[idx][:, :dim], fd[:, :dim], rtol=0, atol=2e-5 * np.abs(f[idx]).max())


def test_mirror_energy_does_not_depend_on_the_ghost_band():
    """Ghosts of particles deeper than the largest H add nothing: a wider band gives the same energy and forces
    (so the energy is continuous as particles enter or leave the band)."""
    from ase_sphrelax.domains import Circle

    atoms = _ball_start_with_close_particles(2, 3)
    calc = ALARICCalculator(target_density=lambda x: np.ones(len(x)), dim=2, domain=Circle((0.0, 0.0), 1.0),
                            boundary="mirror", h_tol=1e-14)
    atoms.calc = calc
    e1, f1, g1 = atoms.get_potential_energy(), atoms.get_forces(), len(calc._ghosts[0])
    calc._band *= 2.0
    calc.results.clear()
    e2, f2, g2 = atoms.get_potential_energy(), atoms.get_forces(), len(calc._ghosts[0])
    assert g2 > g1
    assert abs(e2 - e1) <= 1e-12 * abs(e1)
    np.testing.assert_allclose(f2, f1, rtol=0, atol=1e-10 * np.abs(f1).max())


@pytest.mark.parametrize("kind", ["ball", "polygon"])
def test_mirror_map_jacobian_is_the_derivative_of_the_map(kind):
    from ase_sphrelax.models.alaric import mirror_map

    domain = _mirror_domain(2, kind)
    rng = np.random.default_rng(1)
    x = rng.uniform(-1.0, 1.0, (400, 2))
    x = x[np.abs(np.linalg.norm(x, axis=1) - 0.95) < 0.1]
    owner, g, jac, _ = mirror_map(domain, x, 0.2)
    assert len(owner) == len(x)
    step = 1e-6
    for c in range(2):
        xp, xm = x.copy(), x.copy()
        xp[:, c] += step
        xm[:, c] -= step
        fd = (mirror_map(domain, xp, 0.2)[1] - mirror_map(domain, xm, 0.2)[1]) / (2 * step)
        np.testing.assert_allclose(jac[:, :, c], fd, atol=1e-6)
    # radial: the boundary point half-way between particle and ghost, on the ray from the centre
    mid = 0.5 * (g + x)
    np.testing.assert_allclose(domain.phi(mid), 0.0, atol=1e-12)
    cross = x[owner][:, 0] * g[:, 1] - x[owner][:, 1] * g[:, 0]
    np.testing.assert_allclose(cross, 0.0, atol=1e-12)
    if kind == "ball":  # the reflection through the closest point: as far outside as inside
        np.testing.assert_allclose(domain.phi(g), -domain.phi(x), atol=1e-12)


def test_mirror_refuses_a_domain_it_cannot_mirror():
    from ase_sphrelax.domains import Box, Polygon

    with pytest.raises(ValueError, match="boundary='mirror' needs"):
        ALARICCalculator(target_density=lambda x: np.ones(len(x)), dim=2, boundary="mirror",
                         domain=Box((0.0, 0.0), (1.0, 1.0)))
    concave = Polygon([np.array([[0, 0], [2, 0], [2, 2], [1, 1], [0, 2]], float)])
    with pytest.raises(ValueError, match="convex"):
        ALARICCalculator(target_density=lambda x: np.ones(len(x)), dim=2, boundary="mirror", domain=concave)
    with pytest.raises(ValueError, match="boundary must be"):
        ALARICCalculator(target_density=lambda x: np.ones(len(x)), dim=2, boundary="ghosts")


def test_mirror_with_a_particle_at_the_centre():
    """The radial mirror has no ray at the centre: a particle there gets no ghost (it is far from the boundary),
    the forces stay FD-exact; a ghost band that reaches the centre is a one-line error."""
    from ase_sphrelax.domains import Circle

    rng = np.random.default_rng(0)

    def disc(n):
        x = rng.normal(size=(n, 2))
        x *= (rng.uniform(0.0, 1.0, (n, 1)) ** 0.5) / np.linalg.norm(x, axis=1)[:, None]
        x[0] = 0.0
        pos = np.zeros((n, 3))
        pos[:, :2] = x
        atoms = Atoms(numbers=np.zeros(n, int), positions=pos, pbc=False)
        atoms.calc = ALARICCalculator(target_density=lambda y: np.ones(len(y)), dim=2, domain=Circle((0, 0), 1.0),
                                      boundary="mirror", h_tol=1e-14)
        return atoms

    atoms = disc(400)
    f = atoms.get_forces()
    fd = calculate_numerical_forces(atoms, eps=1e-6, iatoms=[0, 1, 2], icarts=[0, 1])
    np.testing.assert_allclose(f[[0, 1, 2], :2], fd[:, :2], rtol=0, atol=1e-6 * np.abs(f).max())
    with pytest.raises(ValueError, match="at the mirror's centre .* within the ghost band"):
        disc(60).get_forces()
