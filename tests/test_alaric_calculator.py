"""ALARICCalculator: the ALARIC potential and its exact forces (adaptive H), bad input, hard cases."""
import numpy as np
import pytest
from ase import Atoms
from ase.calculators.fd import calculate_numerical_forces

from ase_sphrelax import ALARICCalculator
from ase_sphrelax.domains import Circle, Box
from ase_sphrelax.models import alaric as model


def _gauss(dim, width=0.6, centre=0.5):
    def density(x):
        return 0.2 + np.exp(-((x - centre) ** 2).sum(axis=1) / (2 * width**2))

    def gradient(x):
        return (-(x - centre) / width**2) * (density(x) - 0.2)[:, None]

    return density, gradient


def _periodic(dim, n_side, seed, jitter=0.25):
    rng = np.random.default_rng(seed)
    n = n_side**dim
    grid = np.stack(np.meshgrid(*[np.arange(n_side)] * dim, indexing="ij"), axis=-1).reshape(n, dim) + 0.5
    grid = (grid + rng.uniform(-jitter, jitter, grid.shape)) / n_side
    pos = np.zeros((n, 3))
    pos[:, :dim] = grid
    cell = np.eye(3)
    pbc = [True] * dim + [False] * (3 - dim)
    return Atoms(numbers=np.zeros(n, int), positions=pos, cell=cell, pbc=pbc)


@pytest.mark.parametrize("dim,n_side", [(1, 40), (2, 9), (3, 5)])
@pytest.mark.parametrize("with_gradient", [True, False])
def test_forces_are_the_negative_gradient_periodic(dim, n_side, with_gradient):
    atoms = _periodic(dim, n_side, seed=dim)
    density, gradient = _gauss(dim)
    calc = ALARICCalculator(target_density=density, dim=dim, target_gradient=gradient if with_gradient else None,
                            h_tol=1e-13, cs2=0.7)
    atoms.calc = calc
    f = atoms.get_forces()
    idx = np.arange(0, len(atoms), max(1, len(atoms) // 5))
    fd = calculate_numerical_forces(atoms, eps=1e-6, iatoms=idx, icarts=list(range(dim)))
    scale = np.abs(f).max()
    np.testing.assert_allclose(f[idx][:, :dim], fd[:, :dim], atol=(1e-7 if with_gradient else 1e-5) * scale)
    assert np.all(f[:, dim:] == 0.0)
    assert calc.results["free_energy"] == calc.results["energy"]
    # the H constraint holds at the solved state
    res = calc.results
    np.testing.assert_allclose(res["number_density"] * res["smoothing_lengths"] ** dim, calc.eta**dim, rtol=1e-9)


@pytest.mark.parametrize("dim", [1, 2, 3])
def test_forces_open_with_domain_wall(dim):
    """Open boundaries, a domain whose wall acts on particles starting outside it."""
    rng = np.random.default_rng(7)
    n = {1: 30, 2: 80, 3: 150}[dim]
    pos = np.zeros((n, 3))
    pos[:, :dim] = rng.uniform(-1.1, 1.1, (n, dim))
    atoms = Atoms(numbers=np.zeros(n, int), positions=pos, pbc=False)
    density, gradient = _gauss(dim, centre=0.0)
    domain = Box([-1.0] * dim, [1.0] * dim) if dim > 1 else None
    calc = ALARICCalculator(target_density=density, dim=dim, target_gradient=gradient, h_tol=1e-13, domain=domain)
    atoms.calc = calc
    f = atoms.get_forces()
    idx = np.arange(0, n, max(1, n // 6))
    fd = calculate_numerical_forces(atoms, eps=1e-7, iatoms=idx, icarts=list(range(dim)))
    np.testing.assert_allclose(f[idx][:, :dim], fd[:, :dim], atol=1e-6 * np.abs(f).max())


def test_energy_minimum_has_rho_proportional_to_target():
    """FIRE on the potential (1D periodic, Eq. 46 with Delta = 0.5): rho / rho* becomes nearly uniform."""
    from ase.optimize import FIRE

    n = 101
    pos = np.zeros((n, 3))
    pos[:, 0] = (np.arange(n) + 0.5) * 2.0 / n
    atoms = Atoms(numbers=np.zeros(n, int), positions=pos, cell=[2.0, 1.0, 1.0], pbc=[True, False, False])
    density, gradient = model.eq46(0.5)
    shifted = (lambda x: density(x - 1.0), lambda x: gradient(x - 1.0))
    calc = ALARICCalculator(target_density=shifted[0], target_gradient=shifted[1], dim=1)
    atoms.calc = calc
    e0 = atoms.get_potential_energy()
    eps0 = calc.results["epsilon"]
    FIRE(atoms, logfile=None, dt=0.002, maxstep=0.01).run(fmax=1e-6, steps=3000)
    assert atoms.get_potential_energy() < e0
    ratio = calc.results["density"] / calc.results["target"]
    # the discrete minimum of the log potential has rho / rho* uniform only to the kernel's smoothing
    # error (measured: 2.4 % with 101 particles, 0.4 % with 303; the paper's form reaches 0.09 % at 101)
    assert ratio.std() / ratio.mean() < 0.03
    assert calc.results["epsilon"] < 1e-2 * eps0


def test_paper_form_is_marked_non_conservative():
    density, gradient = _gauss(1)
    assert ALARICCalculator(target_density=density, dim=1).conservative
    calc = ALARICCalculator(target_density=density, dim=1, form="paper")
    assert not calc.conservative
    atoms = _periodic(1, 30, seed=0)
    atoms.calc = calc
    assert np.all(np.isfinite(atoms.get_forces()))


@pytest.mark.parametrize("target,match", [
    (lambda x: -np.ones(len(x)), "must be >= 0"),
    (lambda x: np.full(len(x), np.nan), "NaN or inf"),
    (lambda x: np.zeros(len(x)), "zero at every particle"),
    (lambda x: np.ones((len(x), 2)), "must return shape"),
])
def test_bad_targets_fail_before_any_step(target, match):
    atoms = _periodic(1, 30, seed=0)
    atoms.calc = ALARICCalculator(target_density=target, dim=1)
    with pytest.raises(ValueError, match=match):
        atoms.get_forces()


def test_bad_parameters():
    density, _ = _gauss(1)
    with pytest.raises(TypeError, match="target_density must be a callable"):
        ALARICCalculator(target_density=3.0, dim=1)
    with pytest.raises(ValueError, match="form must be one of"):
        ALARICCalculator(target_density=density, dim=1, form="other")
    with pytest.raises(TypeError, match="unknown parameter"):
        ALARICCalculator(target_density=density, dim=1, temperature=3)
    with pytest.raises(ValueError, match="cs2"):
        ALARICCalculator(target_density=density, dim=1, cs2=-1.0)


def test_too_few_particles_and_dimension_mismatch():
    density, _ = _gauss(2)
    atoms = Atoms(numbers=[0, 0, 0], positions=[[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0]], pbc=False)
    atoms.calc = ALARICCalculator(target_density=density, dim=2)
    with pytest.raises(ValueError, match="needs more than"):
        atoms.get_forces()
    atoms = _periodic(2, 6, seed=0)
    atoms.positions[0, 2] = 0.1
    atoms.calc = ALARICCalculator(target_density=density, dim=2)
    with pytest.raises(ValueError, match="non-zero coordinates beyond axis 1"):
        atoms.get_forces()


def test_coincident_particles_and_zero_target_region():
    """Two coincident particles and a disc target (zero outside) in a square box: finite forces, no NaN."""
    atoms = _periodic(2, 12, seed=1)
    atoms.positions[1] = atoms.positions[0]

    def disc(x):
        return np.maximum(0.0, 1.0 - ((x - 0.5) ** 2).sum(axis=1) / 0.3**2)

    atoms.calc = ALARICCalculator(target_density=disc, dim=2)
    f = atoms.get_forces()
    e = atoms.get_potential_energy()
    assert np.all(np.isfinite(f)) and np.isfinite(e)


@pytest.mark.parametrize("dim,n_side", [(1, 40), (2, 9), (3, 5)])
def test_least_squares_form_forces_are_the_negative_gradient(dim, n_side):
    atoms = _periodic(dim, n_side, seed=10 + dim)
    density, gradient = _gauss(dim)
    calc = ALARICCalculator(target_density=density, target_gradient=gradient, dim=dim, form="squares", h_tol=1e-13)
    atoms.calc = calc
    f = atoms.get_forces()
    idx = np.arange(0, len(atoms), max(1, len(atoms) // 5))
    fd = calculate_numerical_forces(atoms, eps=1e-6, iatoms=idx, icarts=list(range(dim)))
    np.testing.assert_allclose(f[idx][:, :dim], fd[:, :dim], atol=1e-7 * np.abs(f).max())
    assert calc.conservative


@pytest.mark.parametrize("dim,n_side,form", [(2, 9, "log"), (3, 5, "log"), (2, 9, "squares")])
def test_stress_is_the_strain_derivative(dim, n_side, form):
    from ase.calculators.fd import calculate_numerical_stress

    atoms = _periodic(dim, n_side, seed=20 + dim)
    if dim == 2:
        atoms.cell[2, 2] = 1.0  # rank-3 cell for ASE's stress
    density, gradient = _gauss(dim)
    atoms.calc = ALARICCalculator(target_density=density, target_gradient=gradient, dim=dim, form=form, h_tol=1e-13)
    stress = atoms.get_stress()
    if dim == 3:
        fd = calculate_numerical_stress(atoms, eps=1e-6)
        np.testing.assert_allclose(stress, fd, atol=1e-6 * np.abs(stress).max())
        return
    # 2D: in-plane strains only (ASE's helper also shears z, which a 2D calculator rejects)
    cell0, pos0, vol = atoms.cell.array.copy(), atoms.positions.copy(), atoms.get_volume()
    eps = 1e-6
    for voigt, (i, j) in ((0, (0, 0)), (1, (1, 1)), (5, (0, 1))):
        e = []
        for sign in (1, -1):
            strain = np.eye(3)
            strain[i, j] += sign * eps / (1 if i == j else 2)
            strain[j, i] += 0 if i == j else sign * eps / 2
            atoms.set_cell(cell0 @ strain, scale_atoms=False)
            atoms.positions = pos0 @ strain
            e.append(atoms.get_potential_energy())
        atoms.set_cell(cell0, scale_atoms=False)
        atoms.positions = pos0
        fd = (e[0] - e[1]) / (2 * eps * vol)
        assert abs(stress[voigt] - fd) < 1e-6 * np.abs(stress).max(), (voigt, stress[voigt], fd)


def test_stress_needs_a_periodic_cell_and_a_conservative_form():
    from ase.calculators.calculator import PropertyNotImplementedError

    density, _ = _gauss(1)
    atoms = _periodic(1, 30, seed=0)
    atoms.calc = ALARICCalculator(target_density=density, dim=1, form="paper")
    with pytest.raises(PropertyNotImplementedError, match="stress needs"):
        atoms.get_stress()


def test_small_moves_reuse_the_verlet_list():
    """The default skin is fixed at the first evaluation: a skin that followed the mean H (which changes
    at every step) made a new list at every evaluation, i.e. a rebuild per dynamics step."""
    atoms = _periodic(2, 20, seed=3)
    density, gradient = _gauss(2)
    calc = ALARICCalculator(target_density=density, target_gradient=gradient, dim=2)
    atoms.calc = calc
    atoms.get_forces()
    atoms.get_forces()  # (the first evaluation is one-shot; the list is built at the second)
    nlist = calc.nlist
    rng = np.random.default_rng(0)
    for _ in range(10):
        step = rng.normal(scale=1e-4, size=(len(atoms), 3))
        step[:, 2] = 0.0
        atoms.positions += step
        atoms.get_forces()
    assert calc.nlist is nlist
    assert nlist.builds == 1


def test_results_depend_on_the_starting_h_only_to_the_tolerance():
    """Re-evaluating the same positions from another starting H (the previous result, or the global guess)
    changes energy and forces by no more than the H tolerance allows (default h_tol = 1e-8)."""
    atoms = _periodic(2, 12, seed=8)
    density, gradient = _gauss(2)
    calc = ALARICCalculator(target_density=density, target_gradient=gradient, dim=2)
    calc.calculate(atoms, ["energy", "forces"])
    e1, f1 = calc.results["energy"], calc.results["forces"].copy()
    calc.calculate(atoms, ["energy", "forces"])  # from the converged H
    e2, f2 = calc.results["energy"], calc.results["forces"].copy()
    tight = ALARICCalculator(target_density=density, target_gradient=gradient, dim=2, h_tol=1e-13,
                             mass=calc.mass)
    tight.calculate(atoms, ["energy", "forces"])
    scale = np.abs(tight.results["forces"]).max()
    for e, f in ((e1, f1), (e2, f2)):
        assert abs(e - tight.results["energy"]) <= 1e-9 * abs(tight.results["energy"])
        np.testing.assert_allclose(f, tight.results["forces"], rtol=0, atol=1e-7 * scale)
