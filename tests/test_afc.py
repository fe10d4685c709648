"""AFCRelaxation (ALARIC Sec. 5.1's away-from-closest baseline): the move against brute force, the density
error it removes, its input checks, and that it keeps the particle count and the particles inside."""
import numpy as np
import pytest
from ase import Atoms
from hypothesis import given, settings
from hypothesis import strategies as st

from ase_sphrelax import AFCRelaxation, ALARICCalculator
from ase_sphrelax.domains import Circle
from ase_sphrelax.drivers.afc import away_from_closest


def uniform(x):
    return np.ones(len(x))


def _brute_closest(x_pd, box_d):
    """O(N^2) minimum-image differences to the closest other point."""
    d_ppd = x_pd[:, None, :] - x_pd[None, :, :]
    if box_d is not None:
        d_ppd -= box_d * np.round(d_ppd / box_d)
    dist_pp = np.sqrt((d_ppd**2).sum(axis=2))
    np.fill_diagonal(dist_pp, np.inf)
    c = dist_pp.argmin(axis=1)
    return d_ppd[np.arange(len(x_pd)), c], dist_pp.min(axis=1)


def _disc_atoms(n, seed):
    """``n`` uniformly random particles in the open unit disc (rejection from the square)."""
    xy = np.random.default_rng(seed).uniform(-1, 1, (4 * n, 2))
    xy = xy[(xy**2).sum(axis=1) < 0.999][:n]
    return Atoms(numbers=np.zeros(n, int), positions=np.column_stack([xy, np.zeros(n)]), pbc=False)


def _epsilon(atoms, domain):
    probe = atoms.copy()
    probe.calc = ALARICCalculator(target_density=uniform, dim=2, domain=domain)
    probe.get_potential_energy()
    return probe.calc.results["epsilon"]


@settings(max_examples=60, deadline=None, database=None)
@given(n=st.integers(2, 25), dim=st.integers(1, 3), periodic=st.booleans(), seed=st.integers(0, 10**6),
       duplicate=st.booleans())
def test_away_from_closest_matches_brute_force(n, dim, periodic, seed, duplicate):
    rng = np.random.default_rng(seed)
    box_d = rng.uniform(0.5, 2.0, dim) if periodic else None
    x_pd = rng.uniform(-1, 1, (n, dim)) * (box_d if periodic else 1.0)
    if duplicate:  # a coincident pair, the degenerate case: both get unit vectors, their distance is 0
        x_pd[-1] = x_pd[0]
    away_pd, dist_p = away_from_closest(x_pd, box_d)
    diff_pd, ref_p = _brute_closest(np.mod(x_pd, box_d) if periodic else x_pd, box_d)
    np.testing.assert_allclose(dist_p, ref_p, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(away_pd, axis=1), 1.0, rtol=1e-12)
    apart = ref_p > 1e-9
    # ties (two neighbours at the same distance) are measure zero for random points
    np.testing.assert_allclose(away_pd[apart], diff_pd[apart] / ref_p[apart, None], atol=1e-9)


def test_first_step_is_mu0_spacings_away_from_the_closest():
    atoms = _disc_atoms(50, 3)
    x0 = atoms.positions.copy()
    opt = AFCRelaxation(atoms, uniform, 2, steps=10, mu0=0.2)
    opt.run(1)
    diff_pd, dist_p = _brute_closest(x0[:, :2], None)
    spacing = np.sqrt(np.prod(np.ptp(x0[:, :2], axis=0)) / 50)  # (m / rho*)^(1/2), m = V rho* / N, V the bounding box
    expected = x0[:, :2] + 0.2 * spacing * diff_pd / dist_p[:, None]
    np.testing.assert_allclose(atoms.positions[:, :2], expected, atol=1e-12)
    np.testing.assert_array_equal(atoms.positions[:, 2], 0.0)


def test_afc_lowers_the_density_error_keeps_count_and_stays_inside():
    domain = Circle((0.0, 0.0), 1.0)
    atoms = _disc_atoms(300, 1)
    start = _epsilon(atoms, domain)
    opt = AFCRelaxation(atoms, uniform, 2, steps=200, domain=domain)
    opt.run()
    assert len(atoms) == 300 and opt.nsteps == 200
    assert np.all(np.asarray(domain.phi(atoms.positions)) < 0.0)
    end = _epsilon(atoms, domain)
    assert end < 0.5 * start, (start, end)
    _, dist_p = away_from_closest(atoms.positions[:, :2])
    assert dist_p.min() > 0.3 * dist_p.mean()  # the random start's close pairs are gone


def test_afc_in_a_periodic_box_wraps_and_spreads():
    rng = np.random.default_rng(2)
    n, length = 120, 2.0
    pos = np.zeros((n, 3))
    pos[:, :2] = rng.uniform(0, length, (n, 2))
    atoms = Atoms(numbers=np.zeros(n, int), positions=pos, cell=[length, length, 1.0], pbc=(True, True, False))
    _, d0 = away_from_closest(pos[:, :2], np.array([length, length]))
    AFCRelaxation(atoms, uniform, 2, steps=100).run()
    assert len(atoms) == n
    assert np.all((atoms.positions[:, :2] >= 0) & (atoms.positions[:, :2] < length))
    _, d1 = away_from_closest(atoms.positions[:, :2], np.array([length, length]))
    assert d1.min() > 3 * d0.min() and d1.min() > 0.3 * d1.mean()


def test_two_coincident_particles_move_apart():
    atoms = Atoms(numbers=[0, 0], positions=[[0.5, 0.5, 0], [0.5, 0.5, 0]], cell=[1, 1, 1], pbc=(True, True, False))
    AFCRelaxation(atoms, uniform, 2, steps=5).run(1)
    assert np.linalg.norm(atoms.positions[0] - atoms.positions[1]) > 0.05


@pytest.mark.parametrize("kwargs, error, match", [
    (dict(mu0=0.0), ValueError, "mu0 must be"),
    (dict(mu0=float("nan")), ValueError, "mu0 must be"),
    (dict(mu0=1.5), ValueError, r"mu0 must be in \(0, 1\]"),
    (dict(mu0="big"), TypeError, "mu0 must be"),
    (dict(steps=0), ValueError, "steps must be"),
    (dict(target_density=3.0), TypeError, "target_density must be callable"),
    (dict(dim=3), ValueError, "dim"),
])
def test_bad_inputs_are_one_line_errors(kwargs, error, match):
    atoms = _disc_atoms(10, 0)
    args = dict(target_density=uniform, dim=2)
    args.update(kwargs)
    with pytest.raises(error, match=match) as info:
        AFCRelaxation(atoms, **args)
    assert "\n" not in str(info.value)


def test_one_particle_and_mixed_periodicity_are_refused():
    one = Atoms(numbers=[0], positions=[[0.1, 0.2, 0.0]], pbc=False)
    with pytest.raises(ValueError, match="at least 2 particles"):
        AFCRelaxation(one, uniform, 2)
    mixed = _disc_atoms(10, 0)
    mixed.set_cell([3.0, 3.0, 1.0])
    mixed.pbc = (True, False, False)
    with pytest.raises(ValueError, match="periodic along all 2 axes"):
        AFCRelaxation(mixed, uniform, 2)
    skew = _disc_atoms(10, 0)
    skew.set_cell([[3.0, 0, 0], [1.0, 3.0, 0], [0, 0, 1.0]])
    skew.pbc = (True, True, False)
    with pytest.raises(ValueError, match="orthogonal cell"):
        AFCRelaxation(skew, uniform, 2)
