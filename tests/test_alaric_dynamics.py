"""ALARICDynamics (KDK, CFL, S/F/V, stops, mass reset, splitting), split_particles, WVT, ASE optimisers."""
import itertools

import numpy as np
import pytest
from ase import Atoms

from ase_sphrelax import ALARICCalculator
from ase_sphrelax.domains import Circle
from ase_sphrelax.drivers.alaric_dynamics import ALARICDynamics, TimeStepError
from ase_sphrelax.drivers.wvt import WVTRelaxation
from ase_sphrelax.models import alaric as model
from ase_sphrelax.splitting import SPLIT_COUNT, split_particles, split_pattern


def _line(n, delta, form="paper"):
    pos = np.zeros((n, 3))
    pos[:, 0] = (np.arange(n) + 0.5) * 2.0 / n
    atoms = Atoms(numbers=np.zeros(n, int), positions=pos, cell=[2.0, 1.0, 1.0], pbc=[True, False, False])
    density, gradient = model.eq46(delta)
    atoms.calc = ALARICCalculator(target_density=lambda x: density(x - 1.0), target_gradient=lambda x: gradient(x - 1.0),
                                  dim=1, form=form)
    return atoms


def test_sfv_converges_on_eq46():
    atoms = _line(101, 0.5)
    dyn = ALARICDynamics(atoms, eps_dot_min=1e-7)
    eps0 = atoms.calc.results["epsilon"]
    dyn.run(3000)
    assert dyn.stop_reason in ("epsilon", "epsilon_dot", "max_steps")
    assert dyn.trace[-1]["epsilon"] < 1e-3 * eps0
    assert np.all(np.isfinite(atoms.positions))
    # masses follow the calculator's Eq. 44 mass
    np.testing.assert_allclose(atoms.get_masses(), atoms.calc.mass)


@pytest.mark.parametrize("s,f,v", list(itertools.product([False, True], repeat=3)))
def test_every_ingredient_switches(s, f, v):
    atoms = _line(60, 0.5)
    dyn = ALARICDynamics(atoms, velocity_stop=s, friction=2.0 if f else 0.0, viscosity=v)
    dyn.run(40)
    assert dyn.nsteps == 40 and dyn.stop_reason == "max_steps"
    assert np.all(np.isfinite(atoms.positions)) and np.all(np.isfinite(atoms.get_velocities()))


def test_too_large_timestep_is_reported_with_the_step():
    atoms = _line(60, 0.5)
    dyn = ALARICDynamics(atoms, timestep=10.0)
    with pytest.raises(TimeStepError, match="step 0: timestep 10 exceeds the CFL limit"):
        dyn.run(5)


def test_splitting_stage_multiplies_particles():
    atoms = _line(33, 0.5)
    dyn = ALARICDynamics(atoms, splits=1, eps_dot_min=1e-3, eps_min=1e-3)
    dyn.run(3000)
    assert len(atoms) == 99
    assert {e["n"] for e in dyn.trace} == {33, 99}
    assert dyn.trace[-1]["stage"] == 1


def test_split_patterns():
    for dim in (1, 2, 3):
        pattern = split_pattern(dim)
        assert pattern.shape == (SPLIT_COUNT[dim], dim)
        np.testing.assert_allclose(pattern.sum(axis=0), 0.0, atol=1e-12)  # centred
        np.testing.assert_allclose(np.linalg.norm(pattern[1:], axis=1), 1.0)
    # 1D: a uniform line of spacing dx becomes a uniform line of spacing dx / 3 (Eq. 42 with N_H = 2 H / dx)
    n, dx = 20, 0.1
    pos = np.zeros((n, 3))
    pos[:, 0] = np.arange(n) * dx
    atoms = Atoms(numbers=np.zeros(n, int), positions=pos)
    atoms.set_masses(np.full(n, 3.0))
    new_h = split_particles(atoms, np.full(n, 0.3), np.full(n, 1 / dx), 1)
    assert len(atoms) == 3 * n and new_h.shape == (3 * n,)
    x = np.sort(atoms.positions[:, 0])
    np.testing.assert_allclose(np.diff(x), dx / 3, rtol=1e-12)
    np.testing.assert_allclose(atoms.get_masses(), 1.0)
    # Eq. 42 literally: |q| = 2 H / (p^(1/d) N_H)
    pos2 = np.zeros((5, 3))
    atoms2 = Atoms(numbers=np.zeros(5, int), positions=pos2)
    split_particles(atoms2, np.full(5, 0.3), np.ones(5), 2, n_h=6.0)
    q = np.linalg.norm(atoms2.positions[5:, :2], axis=1)
    np.testing.assert_allclose(q, 2 * 0.3 / (4**0.5 * 6.0))
    assert np.all(atoms2.positions[:, 2] == 0.0)


def test_split_rejects_bad_input():
    atoms = Atoms(numbers=[0, 0], positions=np.zeros((2, 3)))
    with pytest.raises(ValueError, match="shape"):
        split_particles(atoms, np.ones(3), np.ones(2), 1)
    with pytest.raises(ValueError, match="finite and > 0"):
        split_particles(atoms, np.array([1.0, -1.0]), np.ones(2), 1)


def test_ase_optimisers_run_on_the_potential():
    from ase.optimize import FIRE, LBFGS

    for opt_cls, kwargs in ((FIRE, dict(dt=0.002, maxstep=0.01)), (LBFGS, dict(maxstep=0.01, alpha=50.0))):
        atoms = _line(61, 0.5, form="log")
        e0 = atoms.get_potential_energy()
        opt_cls(atoms, logfile=None, **kwargs).run(fmax=1e-4, steps=300)
        assert atoms.get_potential_energy() < e0
        assert np.all(np.isfinite(atoms.positions))


def test_single_particle_at_the_bottom_of_the_well():
    """Delta = 0 (rho* touches zero at x = 1): 101 particles, one sits alone in the well; nothing is NaN."""
    atoms = _line(101, 0.0)
    dyn = ALARICDynamics(atoms, eps_dot_min=1e-6)
    dyn.run(1200)
    x = atoms.positions[:, 0]
    assert np.all(np.isfinite(x))
    centre = np.argmin(np.abs(x - 1.0))
    assert abs(x[centre] - 1.0) < 1e-3  # symmetric start: the middle particle stays at the bottom
    gaps = np.sort(np.abs(x - 1.0))
    assert gaps[1] > 3 * (2.0 / 101) * 0.5  # its neighbours keep away from the well


def test_particle_outside_the_support_is_pulled_in():
    """Disc target vanishing outside r = 0.5, the disc as domain; particles start in the square around it."""
    rng = np.random.default_rng(0)
    n = 300
    pos = np.zeros((n, 3))
    pos[:, :2] = rng.uniform(-0.6, 0.6, (n, 2))

    def disc(x):
        return np.maximum(0.0, 1.0 - (x**2).sum(axis=1) / 0.5**2)

    atoms = Atoms(numbers=np.zeros(n, int), positions=pos, pbc=False)
    atoms.calc = ALARICCalculator(target_density=disc, dim=2, domain=Circle((0, 0), 0.5))
    outside0 = (np.linalg.norm(pos[:, :2], axis=1) > 0.5).sum()
    dyn = ALARICDynamics(atoms)
    dyn.run(400)
    r = np.linalg.norm(atoms.positions[:, :2], axis=1)
    assert outside0 > 50
    assert np.all(np.isfinite(r)) and r.max() < 0.55
    assert (r > 0.5).sum() < 0.1 * outside0


def test_wvt_spreads_a_random_start_in_a_circle():
    rng = np.random.default_rng(1)
    n = 400
    r = np.sqrt(rng.uniform(0, 1, n))
    t = rng.uniform(0, 2 * np.pi, n)
    pos = np.zeros((n, 3))
    pos[:, 0], pos[:, 1] = r * np.cos(t), r * np.sin(t)

    def uniform(x):
        return np.ones(len(x))

    calc_eps = []
    for weight in ("r2", "kernel"):
        atoms = Atoms(numbers=np.zeros(n, int), positions=pos.copy(), pbc=False)
        probe = ALARICCalculator(target_density=uniform, dim=2, domain=Circle((0, 0), 1.0))
        atoms.calc = probe
        e_start = atoms.get_potential_energy() and probe.results["epsilon"]
        WVTRelaxation(atoms, uniform, 2, steps=150, weight=weight, domain=Circle((0, 0), 1.0)).run()
        assert np.linalg.norm(atoms.positions[:, :2], axis=1).max() <= 1.0
        atoms.get_potential_energy()
        calc_eps.append((e_start, probe.results["epsilon"]))
    for start, end in calc_eps:
        assert end < 0.3 * start
    with pytest.raises(ValueError, match="weight must be one of"):
        WVTRelaxation(Atoms(), uniform, 2, weight="gauss")


def test_a_particle_at_rest_without_force_sets_no_cfl_limit():
    """Regression: the symmetric line's middle particle (zero force, zero velocity) once gave dt = 0."""
    atoms = _line(61, 0.0, form="log")
    dyn = ALARICDynamics(atoms)
    dyn._accel[:] = 0.0
    dyn._accel[0, 0] = 1.0
    assert dyn.cfl_timestep() > 0.0
    dyn.run(200)
    assert dyn.time > 0.1


def test_friction_alone_converges():
    atoms = _line(101, 0.5)
    dyn = ALARICDynamics(atoms, velocity_stop=False, viscosity=False, eps_dot_min=1e-6)
    dyn.run(4000)
    assert dyn.stop_reason in ("epsilon", "epsilon_dot")


def test_run_continues_after_a_step_cap():
    atoms = _line(61, 0.5)
    dyn = ALARICDynamics(atoms)
    dyn.run(20)
    assert dyn.stop_reason == "max_steps"
    dyn.run(20)
    assert dyn.nsteps == 40


def test_wall_time_cap_stops_the_run():
    atoms = _line(61, 0.5)
    dyn = ALARICDynamics(atoms, max_wall=1e-9)
    assert not dyn.run(20)
    assert dyn.stop_reason == "max_wall" and dyn.nsteps == 0
    with pytest.raises(ValueError, match="max_wall"):
        ALARICDynamics(atoms, max_wall=-1.0)


def test_start_atoms_and_polish():
    from ase_sphrelax.drivers.alaric_dynamics import polish_least_squares, start_atoms

    for dim, n in ((1, 50), (2, 120), (3, 200)):
        atoms, origin, domain = start_atoms(n, dim)
        assert len(atoms) == n and origin.shape == (dim,)
        assert np.all(atoms.positions[:, dim:] == 0.0)
    atoms = _line(101, 0.5, form="log")
    ALARICDynamics(atoms, eps_dot_min=1e-6).run(2000)
    res = atoms.calc.results
    before = res["epsilon"]
    density, gradient = model.eq46(0.5)
    eps, trace, calls = polish_least_squares(atoms, density, 1, model.reset_mass(res["target"], res["number_density"]),
                                             gradient, origin=[-1.0], steps=500)
    assert eps < 0.1 * before and calls == 500 and trace[-1]["epsilon"] >= eps
