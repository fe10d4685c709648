"""WVT's step schedules (linear, Diehl's adaptive reduction and stop) and its mirror-ghost edge."""
import numpy as np
import pytest
from ase import Atoms

from ase_sphrelax.domains import Circle
from ase_sphrelax.drivers.wvt import DIEHL_REDUCTION, WVTRelaxation


def _uniform(x):
    return np.ones(len(x))


def _random_disc(n, seed=0):
    rng = np.random.default_rng(seed)
    r, t = np.sqrt(rng.uniform(0, 1, n)), rng.uniform(0, 2 * np.pi, n)
    pos = np.zeros((n, 3))
    pos[:, 0], pos[:, 1] = r * np.cos(t), r * np.sin(t)
    return Atoms(numbers=np.zeros(n, int), positions=pos, pbc=False)


def test_linear_is_the_default_and_goes_to_zero():
    atoms = _random_disc(100)
    opt = WVTRelaxation(atoms, _uniform, 2, steps=10, domain=Circle((0, 0), 1.0))
    assert opt.schedule_kind == "linear"
    mus = []
    opt.attach(lambda: mus.append(opt.mu), interval=1)
    opt.run()
    # mu of step i (0-based) is mu0 (1 - i / steps); the observer also sees the start
    np.testing.assert_allclose(mus[1:], opt.mu0 * (1.0 - np.arange(10) / 10.0))
    assert opt.nsteps == 10 and not opt.stopped


def test_diehl_reduces_mu_only_when_the_count_of_large_moves_grows_and_stops_on_small_moves():
    opt = WVTRelaxation(_random_disc(200), _uniform, 2, steps=100, schedule="diehl", domain=Circle((0, 0), 1.0))
    mu0 = opt.mu
    n = 200
    for count in (50, 30, 40, 40, 60):  # grows twice: 30 -> 40 and 40 -> 60
        moves = np.full(n, 0.05)
        moves[:count] = 0.2  # above a tenth of the spacing
        opt._diehl_update(moves)
    assert opt.mu == pytest.approx(mu0 * DIEHL_REDUCTION**2)
    assert not opt.stopped and not opt.converged()
    moves = np.full(n, 1e-4)
    moves[:1] = 1.0  # 1 of 200 (0.5 %) above a thousandth of the spacing: below 1 %
    opt._diehl_update(moves)
    assert opt.stopped and opt.converged()


def test_diehl_run_stops_by_its_criterion_before_the_cap():
    atoms = _random_disc(300)
    # mu0 5x the default: large enough that the count of large moves grows now and then (with the default
    # 0.002 it only falls from this start, and mu is never reduced)
    opt = WVTRelaxation(atoms, _uniform, 2, steps=20000, mu0=0.01, schedule="diehl", boundary="mirror",
                        domain=Circle((0, 0), 1.0))
    opt.run()
    assert opt.stopped and opt.nsteps < 20000
    assert opt.mu < 0.9 * opt.mu0  # reduced at least twice
    assert np.linalg.norm(atoms.positions[:, :2], axis=1).max() <= 1.0


def test_a_mirror_ghost_pushes_an_edge_particle_inward():
    """Two particles 0.1 from the circle: without ghosts they push each other outwards (and are put back on
    the inside), with ghosts each one's own image, 0.2 away, pushes it inwards."""
    ends = {}
    for boundary in ("project", "mirror"):
        atoms = Atoms(numbers=[0, 0], positions=[[0.9, 0, 0], [-0.9, 0, 0]], pbc=False)
        WVTRelaxation(atoms, _uniform, 2, steps=1, domain=Circle((0, 0), 1.0), boundary=boundary).run()
        ends[boundary] = atoms.positions[0, 0]
    assert ends["project"] > 0.9
    assert ends["mirror"] < 0.9
    np.testing.assert_allclose(atoms.positions[1, 0], -ends["mirror"])  # symmetric


def test_mirror_keeps_particles_off_the_circle():
    """Without ghosts WVT packs particles against the circle; with ghosts they stay about half a spacing in."""
    near = {}
    for boundary in ("project", "mirror"):
        atoms = _random_disc(300, seed=1)
        WVTRelaxation(atoms, _uniform, 2, steps=400, domain=Circle((0, 0), 1.0), boundary=boundary).run()
        spacing = np.sqrt(np.pi / 300)
        near[boundary] = int(np.count_nonzero(1.0 - np.linalg.norm(atoms.positions[:, :2], axis=1) < 0.1 * spacing))
    assert near["project"] >= 10
    assert near["mirror"] == 0


@pytest.mark.parametrize("kwargs, name", [(dict(schedule="cosine"), "schedule"), (dict(boundary="ghost"), "boundary"),
                                          (dict(boundary="mirror"), "boundary")])
def test_bad_input(kwargs, name):
    with pytest.raises(ValueError, match=name):
        WVTRelaxation(_random_disc(10), _uniform, 2, **kwargs)
