"""FanRelaxation (Eq. 2.4): E decreases (Eq. 3.18) until the fixed step c*h makes it oscillate;
bounded relaxations keep particles inside with the boundary layer where Sec. 4.2 puts it."""
import numpy as np
import pytest
from ase.constraints import FixAtoms

from ase_sphrelax import FanCalculator, FanRelaxation
from ase_sphrelax.analysis import Quality
from ase_sphrelax.build import fill, periodic_box
from ase_sphrelax.domains import Circle, Polygon
from ase_sphrelax.drivers import make_optimizer


def energies_along(opt, atoms, steps):
    energies = [atoms.get_potential_energy()]
    opt.attach(lambda: energies.append(atoms.get_potential_energy()))
    opt.run(fmax=0.0, steps=steps)
    return np.array(energies[1:])


def jittered_box(seed=3):
    atoms = periodic_box((20, 20), dx=1.0, jitter=0.2, seed=seed)
    atoms.calc = FanCalculator(h=2.6, dx=1.0)
    return atoms


def test_each_step_moves_the_fastest_particle_by_c_h():
    """Eq. 2.5: ||dr||_{2,inf} = c h."""
    atoms = jittered_box()
    before = atoms.positions.copy()
    FanRelaxation(atoms, c=0.01, logfile=None).run(fmax=0.0, steps=1)
    assert np.linalg.norm(atoms.positions - before, axis=1).max() == pytest.approx(0.01 * 2.6, rel=1e-12)


def test_total_error_decreases_along_the_trajectory_at_first():
    """Eq. 3.18: dE/dt = -|grad E|^2 <= 0 in continuous time; the discrete steps follow it early on."""
    atoms = jittered_box()
    energies = energies_along(FanRelaxation(atoms, c=0.01, logfile=None), atoms, 200)
    assert np.all(np.diff(energies[:10]) < 0)
    assert energies[-1] < 0.5 * energies[0]


def test_fixed_step_length_oscillates_at_a_floor_set_by_c():
    """With the fixed step c*h, Eq. 2.4 cannot settle: near the minimum E goes up about every
    other step, and the size of the oscillation grows with c (measured: E range over the last
    200 of 2000 steps 0.015 at c = 0.005, 0.33 at c = 0.05, for E - E_min ~ 0.05)."""
    amplitude = {}
    for c in (0.005, 0.05):
        atoms = jittered_box()
        energies = energies_along(FanRelaxation(atoms, c=c, logfile=None), atoms, 600)
        tail = energies[-100:]
        assert (np.diff(tail) > 0).mean() > 0.3  # not monotone: it oscillates
        amplitude[c] = np.ptp(tail)
    assert amplitude[0.05] > 3 * amplitude[0.005]


def test_fix_atoms_constraint_is_respected():
    atoms = jittered_box()
    atoms.set_constraint(FixAtoms(indices=range(50)))
    before = atoms.positions.copy()
    FanRelaxation(atoms, logfile=None).run(fmax=0.0, steps=5)
    moved = np.linalg.norm(atoms.positions - before, axis=1)
    assert np.all(moved[:50] == 0.0) and moved[50:].max() > 0


def test_ase_optimisers_drive_the_same_calculator():
    for name in ("fire", "lbfgs", "bfgs"):
        atoms = periodic_box((8, 8), dx=1.0, jitter=0.2, seed=1)
        atoms.calc = FanCalculator(h=2.6, dx=1.0)
        e0 = atoms.get_potential_energy()
        make_optimizer(name, atoms).run(fmax=1e-6, steps=60)
        assert atoms.get_potential_energy() < 0.5 * e0, name


@pytest.fixture(scope="module")
def relaxed_circle():
    dx = 1 / 64
    domain = Circle((0.5, 0.5), 0.2)
    atoms = fill(domain, dx, jitter=0.1, seed=1)
    atoms.calc = FanCalculator(h=2.6 * dx, dx=dx, domain=domain)
    e0 = atoms.get_potential_energy()
    FanRelaxation(atoms, c=0.01, logfile=None).run(fmax=0.0, steps=400)
    return atoms, domain, dx, e0


def test_bounded_relaxation_keeps_every_particle_inside(relaxed_circle):
    atoms, domain, dx, e0 = relaxed_circle
    assert domain.phi(atoms.positions).max() <= 0.05 * dx
    assert atoms.get_potential_energy() < e0


def test_boundary_layer_sits_half_a_layer_spacing_from_the_boundary(relaxed_circle):
    """Sec. 4.2 / Fig. 3: the first layer sits at half a layer spacing (0.5 dp for a square
    lattice, sqrt(3)/4 a = 0.465 dp for a hexagonal one), not at a fixed dx/2."""
    atoms, domain, dx, _ = relaxed_circle
    q = Quality(2.6 * dx, dx=dx, domain=domain).compute(atoms).summary()
    assert 0.40 <= q["boundary_distance_mean"] <= 0.52
    assert q["boundary_distance_min"] > 0.2


def test_relaxation_improves_interior_kernel_sums(relaxed_circle):
    atoms, domain, dx, _ = relaxed_circle
    relaxed = Quality(2.6 * dx, dx=dx, domain=domain).compute(atoms).summary()
    start = Quality(2.6 * dx, dx=dx, domain=domain).compute(fill(domain, dx, jitter=0.1, seed=1)).summary()
    # the mean of |Σ V W - 1| keeps an offset (boundary particles take more volume, the
    # interior is compressed); the spread of Σ V W is what relaxation removes
    assert relaxed["kernel_sum_std"] < 0.5 * start["kernel_sum_std"]
    assert relaxed["gradient_error_mean"] < 0.2 * start["gradient_error_mean"]


# -- hard cases (issue item 14) ------------------------------------------------------------
def _relax_bounded(domain, atoms, h, dx, steps, c=0.01):
    atoms.calc = FanCalculator(h=h, dx=dx, domain=domain)
    opt = FanRelaxation(atoms, c=c, logfile=None)
    opt.run(fmax=0.0, steps=steps)
    assert np.all(np.isfinite(atoms.positions)) and np.isfinite(atoms.get_potential_energy())
    return atoms


def test_ten_degree_wedge_corner_stays_finite_and_inside():
    dx = 0.02
    tip = np.array([0.0, 0.0])
    half = np.radians(5.0)
    wedge = Polygon([[tip, (1.0, -np.tan(half)), (1.0, np.tan(half))]])
    atoms = fill(wedge, dx / 2, jitter=0.1, seed=0)  # fine enough to put particles in the corner
    atoms.info["dx"] = dx / 2
    atoms = _relax_bounded(wedge, atoms, 2.6 * dx / 2, dx / 2, 300)
    assert wedge.phi(atoms.positions).max() <= 0.05 * dx / 2


def test_particles_several_h_outside_are_pulled_back_in():
    """Outside, Eq. 4.3 pulls with the constant force 2 W1(0) vt: a particle 3h out returns."""
    dx = 1 / 64
    h = 2.6 * dx
    domain = Circle((0.5, 0.5), 0.2)
    atoms = fill(domain, dx, jitter=0.1, seed=2)
    outside = np.arange(0, len(atoms), 40)
    direction = atoms.positions[outside, :2] - 0.5
    direction /= np.linalg.norm(direction, axis=1)[:, None]
    atoms.positions[outside, :2] = 0.5 + (0.2 + 3 * h) * direction
    assert domain.phi(atoms.positions).max() > 2.9 * h
    atoms = _relax_bounded(domain, atoms, h, dx, 700, c=0.02)
    assert domain.phi(atoms.positions).max() <= 0.05 * dx


def test_all_particles_inside_one_kernel_radius_spread_out():
    dx = 0.02
    h = 2.6 * dx
    domain = Circle((0.0, 0.0), 0.2)
    rng = np.random.default_rng(0)
    from ase import Atoms

    r_pc = np.zeros((40, 3))
    r_pc[:, :2] = rng.uniform(-0.3 * h, 0.3 * h, (40, 2))
    atoms = Atoms(numbers=np.zeros(40, int), positions=r_pc)
    atoms.calc = FanCalculator(h=h, dx=dx, domain=domain)
    e0 = atoms.get_potential_energy()
    atoms = _relax_bounded(domain, atoms, h, dx, 300)
    spread = np.linalg.norm(atoms.positions[:, :2], axis=1).max()
    assert spread > h and atoms.get_potential_energy() < 0.2 * e0


@pytest.mark.parametrize("h_over_dx", [1.2, 4.0])
def test_extreme_smoothing_lengths_stay_finite(h_over_dx):
    """h/dx = 1.2: few neighbours, many pairs beyond the support; h/dx = 4: about 50 neighbours."""
    dx = 1 / 40
    domain = Circle((0.5, 0.5), 0.2)
    atoms = fill(domain, dx, jitter=0.2, seed=0)
    atoms.calc = FanCalculator(h=h_over_dx * dx, dx=dx, domain=domain)
    e0 = atoms.get_potential_energy()
    atoms = _relax_bounded(domain, atoms, h_over_dx * dx, dx, 200)
    assert atoms.get_potential_energy() < e0
    assert domain.phi(atoms.positions).max() <= 0.05 * dx


def test_zero_forces_stop_the_relaxation_without_moving():
    atoms = periodic_box((6, 6), dx=1.0)  # a perfect lattice: all forces vanish by symmetry
    atoms.calc = FanCalculator(h=2.6, dx=1.0)
    before = atoms.positions.copy()
    opt = FanRelaxation(atoms, logfile=None)
    opt.run(fmax=1e-12, steps=10)
    assert opt.last_step == 0.0 and np.array_equal(atoms.positions, before)


@pytest.mark.parametrize("kwargs, match", [(dict(c=0.0), "c must be"), (dict(c=-1), "c must be"),
                                           (dict(c=0.01, h=-1.0), "h must be")])
def test_bad_driver_parameters(kwargs, match):
    atoms = jittered_box()
    with pytest.raises(ValueError, match=match):
        FanRelaxation(atoms, **kwargs)


def test_unknown_optimizer_name_is_rejected():
    with pytest.raises(ValueError, match="optimizer must be one of"):
        make_optimizer("adam", jittered_box())


def test_quasi_newton_optimisers_accept_steps_longer_than_one_length_unit():
    """ASE's LBFGS refuses maxstep > 1 (Angstrom sanity check); SPH units have no such scale."""
    atoms = periodic_box((8, 8), dx=10.0, jitter=0.2, seed=1)
    atoms.calc = FanCalculator(h=26.0, dx=10.0)
    opt = make_optimizer("lbfgs", atoms)
    assert opt.maxstep == pytest.approx(10 * 0.05 * 26.0)
    e0 = atoms.get_potential_energy()
    opt.run(fmax=0.0, steps=20)
    assert atoms.get_potential_energy() < e0


def test_lean_run_loop_matches_ases_loop():
    """FanRelaxation's own loop (one force request per step) gives ASE's trajectory, observer
    calls and log lines."""
    import io

    from ase.optimize.optimize import Optimizer

    runs = []
    for lean in (True, False):
        atoms = jittered_box()
        log = io.StringIO()
        opt = FanRelaxation(atoms, c=0.01, logfile=log)
        calls = []
        opt.attach(lambda: calls.append(opt.nsteps))
        converged = opt.run(fmax=0.0, steps=7) if lean else Optimizer.run(opt, fmax=0.0, steps=7)
        runs.append((atoms.positions.copy(), calls, len(log.getvalue().splitlines()), converged, opt.nsteps))
    (r_lean, calls_lean, lines_lean, conv_lean, n_lean), (r_ase, calls_ase, lines_ase, conv_ase, n_ase) = runs
    np.testing.assert_array_equal(r_lean, r_ase)
    assert calls_lean == calls_ase == list(range(8))
    assert lines_lean == lines_ase == 9  # header + steps 0..7
    assert conv_lean == conv_ase and n_lean == n_ase == 7


def test_fire_caps_each_particles_move_not_the_whole_step():
    """ASE's FIRE caps the norm of the 3N step; make_optimizer scales that cap by sqrt(N), so that a
    large system moves as far per step as a small one (first step: every particle by c h)."""
    from ase import Atoms
    from ase.calculators.calculator import Calculator, all_changes

    class Uniform(Calculator):
        implemented_properties = ["energy", "forces"]

        def calculate(self, atoms=None, properties=("energy",), system_changes=all_changes):
            Calculator.calculate(self, atoms, properties, system_changes)
            self.results = dict(energy=-float(self.atoms.positions[:, 0].sum()),
                                forces=np.tile([1.0, 0.0, 0.0], (len(self.atoms), 1)))

    for n in (10, 10000):
        atoms = Atoms("X" * n, positions=np.random.default_rng(0).uniform(0, 10, (n, 3)))
        atoms.calc = Uniform()
        start = atoms.positions.copy()
        make_optimizer("fire", atoms, c=0.01, h=1.0).run(fmax=0.0, steps=1)
        np.testing.assert_allclose(atoms.positions - start, np.tile([0.01, 0, 0], (n, 1)), rtol=1e-12, atol=1e-15)


def _eq24_step(atoms, c=0.01, h=2.6):
    """Positions after one Eq. 2.4 step from the forces of ``atoms`` as they are now."""
    f_pc = atoms.get_forces()
    return atoms.positions + f_pc * (c * h / np.linalg.norm(f_pc, axis=1).max())


@pytest.mark.parametrize("observer", [False, True], ids=["run", "run with an observer"])
def test_run_steps_from_the_forces_of_each_step(observer):
    """run() hands each step the gradient of the evaluation before it: the same positions as
    steps taken one by one from freshly asked forces."""
    atoms, reference = jittered_box(), jittered_box()
    opt = FanRelaxation(atoms, c=0.01, logfile=None)
    if observer:
        opt.attach(lambda: None)
    opt.run(fmax=0.0, steps=3)
    for _ in range(3):
        reference.positions = _eq24_step(reference)
    np.testing.assert_array_equal(atoms.positions, reference.positions)


def test_irun_steps_from_the_forces_of_atoms_moved_between_yields():
    """The caller may move the atoms between two yields of irun(): the next step takes the
    forces at the moved positions, not the gradient of the evaluation before."""
    atoms = jittered_box()
    steps = FanRelaxation(atoms, c=0.01, logfile=None).irun(fmax=0.0, steps=2)
    next(steps)
    next(steps)
    atoms.positions[:40, 0] += 0.3  # the caller moves some particles
    expected = _eq24_step(atoms)
    next(steps)
    np.testing.assert_allclose(atoms.positions, expected, rtol=0, atol=1e-14)
