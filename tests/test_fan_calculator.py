"""FanCalculator: Eq. 3.8 energy with exact Eq. 3.17 / 4.4 forces and exact stress."""

import numpy as np
import pytest
from ase import Atoms
from ase.calculators.fd import calculate_numerical_forces, calculate_numerical_stress

from ase_sphrelax import FanCalculator
from ase_sphrelax.boundary import gamma_and_gradient
from ase_sphrelax.build import periodic_box
from ase_sphrelax.domains import Box, Circle, Polygon, Sphere
from ase_sphrelax.kernels import get_kernel
from ase_sphrelax.models.fan import CORE_DISTANCE, CORE_STIFFNESS, WALL_OPENING, WALL_WEIGHT

from conftest import random_periodic


def brute_force_energy(atoms, h, v0, volume, dim, domain=None, boundary_term="level_set"):
    """Eq. 3.8 by an O(N^2) minimum-image double sum (cells larger than 2h); ``"gamma"``: the boundary
    part ``2 v0 kappa (1 - gamma + W1(0) max(phi, 0) + core)`` with gamma from the unmerged segments/triangles of
    the wall: a Polygon's opening at ``WALL_OPENING dp`` (FanModel.wall), another domain itself."""
    kernel = get_kernel("wendland_c2", dim)
    r_pc = atoms.positions[:, :dim]
    d_ppc = r_pc[None] - r_pc[:, None]
    pbc = np.asarray(atoms.pbc[:dim])
    if pbc.any():
        lengths = np.diag(atoms.cell.array)[:dim]
        d_ppc = d_ppc - np.where(pbc, lengths * np.round(d_ppc / np.where(pbc, lengths, 1.0)), 0.0)
    energy = v0 * v0 * kernel.w(np.linalg.norm(d_ppc, axis=2), h).sum() - volume
    if domain is not None and boundary_term == "gamma":
        wall = domain.opening(WALL_OPENING * v0 ** (1 / dim)) if isinstance(domain, Polygon) else domain
        gamma_p = gamma_and_gradient(atoms.positions, wall, h)[0]
        phi_p = wall.phi(atoms.positions)
        d0 = CORE_DISTANCE * v0 ** (1 / dim)
        core_p = CORE_STIFFNESS / (2 * d0 * h) * np.maximum(d0 + phi_p, 0.0) ** 2
        energy += 2 * v0 * WALL_WEIGHT * (1.0 - gamma_p + np.maximum(phi_p, 0.0) * kernel.w1(0.0, h) + core_p).sum()
    elif domain is not None:
        energy += 2 * v0 * kernel.w1_tail_integral(-domain.phi(atoms.positions), h).sum()
    return energy


def bounded_atoms(domain, n, rng, spread=1.3):
    lo, hi = domain.bounds
    centre, half = (lo + hi) / 2, (hi - lo) / 2 * spread
    r_pc = np.zeros((n, 3))
    r_pc[:, : domain.dim] = rng.uniform(centre - half, centre + half, (n, domain.dim))
    return Atoms(numbers=np.zeros(n, int), positions=r_pc, pbc=False)


def in_plane_numerical_stress(atoms, eps):
    """Central differences of E over the in-plane strains of a 2D cell: Voigt xx, yy, xy (as ASE's helper)."""
    cell0, volume = atoms.cell.array.copy(), atoms.get_volume()
    out = []
    for i, j in ((0, 0), (1, 1), (0, 1)):
        energies = []
        for sign in (1, -1):
            strain = np.eye(3)
            strain[i, j] += sign * eps
            atoms.set_cell(cell0 @ strain, scale_atoms=True)
            energies.append(atoms.get_potential_energy())
        out.append((energies[0] - energies[1]) / (2 * eps * volume))
    atoms.set_cell(cell0, scale_atoms=True)
    return np.array(out)


@pytest.mark.parametrize("dim", [1, 2, 3])
@pytest.mark.parametrize("dx", [0.9, None])
def test_periodic_forces_and_stress_are_exact_derivatives(dim, dx):
    rng = np.random.default_rng(dim)
    atoms = random_periodic({1: 12, 2: 30, 3: 40}[dim], max(dim, 2), rng, skew=0.15 if dim > 1 else 0.0)
    if dim == 1:
        atoms.positions[:, 1] = 0.0
        atoms.pbc = (True, False, False)
    atoms.calc = FanCalculator(h=2.6, dx=dx, dim=dim)
    forces = atoms.get_forces()
    # finite differences along the dim axes only: moving a 2D particle off z = 0 is an error
    numeric = calculate_numerical_forces(atoms, eps=1e-6, icarts=range(dim))
    np.testing.assert_allclose(forces[:, :dim], numeric[:, :dim], atol=1e-7)
    assert np.all(forces[:, dim:] == 0.0)
    assert np.abs(forces).max() > 1e-2  # not a trivially zero comparison
    if dim == 3:
        stress = atoms.get_stress()
        np.testing.assert_allclose(stress, calculate_numerical_stress(atoms, eps=1e-6), atol=1e-7)
    elif dim == 2:  # in-plane strains only: a strain with a z component moves 2D particles off z = 0
        stress = atoms.get_stress()
        np.testing.assert_allclose(stress[[0, 1, 5]], in_plane_numerical_stress(atoms, 1e-6), atol=1e-7)
        assert np.all(stress[[2, 3, 4]] == 0.0)
    assert atoms.get_potential_energy() == pytest.approx(atoms.calc.results["free_energy"])
    assert atoms.calc.results["energies"].sum() == pytest.approx(atoms.get_potential_energy())


@pytest.mark.parametrize("domain", [
    Circle((0.5, 0.5), 0.2),
    Box((0.0, 0.0), (0.3, 0.2)),
    Polygon([[(0, 0), (0.3, 0), (0.3, 0.3), (0.15, 0.1), (0, 0.3)]]),  # non-convex, sharp corner
    Sphere((0.0, 0.0, 0.0), 0.15),
    Box((0.0, 0.0, 0.0), (0.2, 0.2, 0.1)),
], ids=["circle", "box2d", "polygon", "sphere", "box3d"])
@pytest.mark.parametrize("term", ["level_set", "auto"])
def test_bounded_forces_are_exact_derivatives_inside_and_outside(domain, term):
    """Eq. 4.4 is -grad of Eq. 3.8, also for particles outside the domain (phi > 0); the default
    ("auto": exact gamma for the box and polygon, the level set for the circle and sphere) too."""
    rng = np.random.default_rng(11)
    dx = 0.03 if domain.dim == 2 else 0.04
    atoms = bounded_atoms(domain, 40, rng)
    calc = FanCalculator(h=2.6 * dx, dx=dx, domain=domain, dim=domain.dim, boundary_term=term)
    expected = "level_set" if term == "level_set" or isinstance(domain, (Circle, Sphere)) else "gamma"
    assert calc.model.boundary_term == expected
    atoms.calc = calc
    phi_p = domain.phi(atoms.positions)
    assert (phi_p > 0).sum() >= 3 and (phi_p < 0).sum() >= 3
    forces = atoms.get_forces()
    numeric = calculate_numerical_forces(atoms, eps=1e-7, icarts=range(domain.dim))
    scale = np.abs(forces).max()
    np.testing.assert_allclose(forces[:, : domain.dim], numeric[:, : domain.dim], atol=1e-6 * scale)
    assert np.all(forces[:, domain.dim:] == 0.0)
    assert atoms.get_potential_energy() == pytest.approx(
        brute_force_energy(atoms, 2.6 * dx, dx**domain.dim, domain.volume, domain.dim, domain, expected), rel=1e-12)


def test_energy_matches_brute_force_double_sum():
    rng = np.random.default_rng(5)
    atoms = random_periodic(150, 2, rng)
    atoms.calc = FanCalculator(h=2.3, dx=1.0)
    assert atoms.get_potential_energy() == pytest.approx(
        brute_force_energy(atoms, 2.3, 1.0, atoms.cell.volume, 2), rel=1e-12)


@pytest.mark.parametrize("h, v_c", [(1.5, 0.878028), (2.6, 0.991235)])
def test_hexagonal_lattice_energy_gives_table_2_characteristic_volume(h, v_c):
    """Eq. 5.2: at unit particle volume E/N = 1/v_c - 1 (Table 2, hexagonal column)."""
    atoms = periodic_box((6, 8), dx=1.0, lattice="hexagonal")
    atoms.calc = FanCalculator(h=h, dx=1.0)
    per_particle = atoms.get_potential_energy() / len(atoms)
    assert 1.0 / (per_particle + 1.0) == pytest.approx(v_c, abs=1e-6)
    np.testing.assert_allclose(atoms.get_forces(), 0.0, atol=1e-12)  # a lattice is an equilibrium


def test_coincident_particles_give_finite_forces():
    atoms = Atoms("X3", positions=[(1, 1, 0), (1, 1, 0), (1.5, 1, 0)], cell=[4, 4, 1], pbc=(True, True, False))
    atoms.calc = FanCalculator(h=2.0, dx=1.0)
    forces = atoms.get_forces()
    assert np.all(np.isfinite(forces)) and np.isfinite(atoms.get_potential_energy())


def test_two_dimensional_atoms_off_the_plane_are_an_error_never_flattened():
    """Issue 10 item 1: a 2D particle at z != 0 is refused (it used to be projected silently)."""
    rng = np.random.default_rng(2)
    atoms = random_periodic(20, 2, rng)
    atoms.calc = FanCalculator(h=2.6, dx=1.0, dim=2)
    assert np.all(atoms.get_forces()[:, 2] == 0.0)
    atoms.positions[3, 2] = 0.4
    with pytest.raises(ValueError, match=r"2D system needs every particle at z = 0.*particle 3 at z = 0.4"):
        atoms.get_potential_energy()


def test_stress_is_refused_for_bounded_domains():
    from ase.calculators.calculator import PropertyNotImplementedError

    atoms = bounded_atoms(Circle((0, 0), 1.0), 5, np.random.default_rng(0))
    atoms.calc = FanCalculator(h=0.3, dx=0.1, domain=Circle((0, 0), 1.0))
    with pytest.raises(PropertyNotImplementedError, match="periodic"):
        atoms.get_stress()


@pytest.mark.parametrize("kwargs, match", [
    (dict(h=0.0), "h must be"),
    (dict(h=-1.0), "h must be"),
    (dict(h=float("nan")), "h must be"),
    (dict(h=1.0, dx=0.0), "dx must be"),
    (dict(h=1.0, dx=-2.0), "dx must be"),
    (dict(h=1.0, dim=4), "dim must be"),
    (dict(h=1.0, dim=0), "dim must be"),
    (dict(h=1.0, kernel="gauss"), "kernel must be"),
    (dict(h=1.0, dim=3, domain=Circle((0, 0), 1.0)), "domain is 2D"),
])
def test_bad_parameters_are_rejected_by_name(kwargs, match):
    with pytest.raises(ValueError, match=match):
        FanCalculator(**kwargs)


def test_unknown_parameter_is_rejected():
    with pytest.raises(TypeError, match="unknown parameter.*'cutoff'"):
        FanCalculator(h=1.0, cutoff=2.0)
    calc = FanCalculator(h=1.0)
    with pytest.raises(TypeError, match="unknown parameter"):
        calc.set(smoothing=3)


def test_bad_atoms_are_rejected_before_work():
    calc = FanCalculator(h=1.0, dx=1.0)
    empty = Atoms(cell=[3, 3, 1], pbc=(True, True, False))
    with pytest.raises(ValueError, match="at least one particle"):
        calc.get_potential_energy(empty)
    nan = Atoms("X2", positions=[(0, 0, 0), (np.nan, 0, 0)], cell=[3, 3, 1], pbc=(True, True, False))
    with pytest.raises(ValueError, match="finite"):
        calc.get_potential_energy(nan)
    free = Atoms("X2", positions=[(0, 0, 0), (0.5, 0, 0)])
    with pytest.raises(ValueError, match="dx=None"):
        FanCalculator(h=1.0).get_potential_energy(free)


@pytest.mark.parametrize("side", [12, 160])  # 144 particles (serial), 25600 (threaded, >= PARALLEL_MIN)
def test_one_shot_scan_and_verlet_list_agree(side):
    """The first evaluation fuses the pair sums into the bin scan; later ones use the Verlet list."""
    atoms = periodic_box(side, dx=1.0, jitter=0.25, seed=4)
    moved = atoms.copy()
    moved.positions[:, :2] += np.random.default_rng(0).uniform(-0.01, 0.01, (len(atoms), 2))
    reused = FanCalculator(h=2.6, dx=1.0, skin=0.3)
    reused.get_forces(atoms)                    # one-shot scan
    f_list = reused.get_forces(moved)           # Verlet list
    assert reused.nlist.builds == 1
    fresh = FanCalculator(h=2.6, dx=1.0)
    f_scan = fresh.get_forces(moved)            # one-shot scan on the same positions
    np.testing.assert_allclose(f_list, f_scan, rtol=0, atol=1e-12 * np.abs(f_scan).max())
    assert reused.get_potential_energy(moved) == pytest.approx(fresh.get_potential_energy(moved), rel=1e-13)


@pytest.mark.parametrize("value", ["2.6", None, True])
def test_non_numbers_are_rejected_as_type_errors(value):
    with pytest.raises(TypeError, match="h must be a positive finite number"):
        FanCalculator(h=value)


@pytest.mark.parametrize("domain", [Circle((0.5, 0.5), 0.2), Box((0.0, 0.0), (0.3, 0.2)),
                                    Sphere((0.5, 0.5, 0.5), 0.1)], ids=["circle", "box2d", "sphere"])
def test_forces_alone_skip_the_energy_and_equal_the_full_evaluation(domain):
    """An optimiser's get_forces() asks for forces only: no energy terms are computed (no 'energy' in the
    results), the forces are those of an energy-and-forces evaluation to round-off, and the energy asked for
    afterwards is computed then. Not bit for bit: the two are separate compiled loops whose a-side sums the compiler
    reassociates for its vector loop (pairs.py's ``_terms``), and on an AVX2 machine (znver3) it ordered them
    differently; on an AVX-512 one they had agreed bit for bit."""
    rng = np.random.default_rng(3)
    dx = 0.03 if domain.dim == 2 else 0.04
    atoms = bounded_atoms(domain, 60, rng)
    full = atoms.copy()
    for a in (atoms, full):
        a.calc = FanCalculator(h=2.6 * dx, dx=dx, domain=domain)
    for _ in range(2):  # one-shot scan, then the stored list
        f_only = atoms.get_forces()
        assert "energy" not in atoms.calc.results and "energies" not in atoms.calc.results
        full.calc.calculate(full, ["energy", "forces"], [])
        f_full = full.calc.results["forces"]
        np.testing.assert_allclose(f_only, f_full, rtol=0, atol=1e-13 * np.abs(f_full).max())
        assert atoms.get_potential_energy() == full.calc.results["energy"]
        atoms.positions[:, : domain.dim] += 0.01 * dx
        full.positions[:, : domain.dim] += 0.01 * dx


@pytest.mark.parametrize("domain", [Circle((0.5, 0.5), 0.2), Sphere((0.5, 0.5, 0.5), 0.1)], ids=["circle", "sphere"])
def test_level_set_term_on_the_particles_near_the_wall_at_the_build_changes_nothing(domain, monkeypatch):
    """The level-set boundary term evaluated on the particles within h + skin of the wall at the list's build
    only (FanCalculator._near_wall) gives the trajectory of the term on every particle, bit for bit."""
    from ase_sphrelax import make_optimizer
    from ase_sphrelax.build import fill

    dx = 0.01 if domain.dim == 2 else 0.02
    runs = []
    for restrict in (True, False):
        atoms = fill(domain, dx, jitter=0.3, seed=1)
        atoms.calc = FanCalculator(h=2.6 * dx, dx=dx, domain=domain)
        if not restrict:
            monkeypatch.setattr(atoms.calc, "_near_wall", lambda state: None)
        make_optimizer("fire", atoms).run(fmax=0.0, steps=40)
        assert atoms.calc.nlist.builds >= 3
        if restrict:
            assert 0 < len(atoms.calc._near) < len(atoms)
        runs.append(atoms.positions.copy())
    assert np.array_equal(runs[0], runs[1])


def test_forces_are_written_into_the_previous_array_when_no_one_holds_it():
    """An evaluation writes its forces into the array of the results it replaces (SPHCalculator.spare_forces): the
    same object, the same bits as into a fresh array; not when someone holds that array (a forces_view, the results'
    array itself), whose values stay, and not at a rebuild of the neighbour list."""
    import weakref

    from ase_sphrelax.build import fill

    domain = Circle((0.5, 0.5), 0.3)
    atoms = fill(domain, 0.02, jitter=0.1, seed=1)
    twin = atoms.copy()
    calc = atoms.calc = FanCalculator(h=0.052, dx=0.02, domain=domain)
    twin.calc = FanCalculator(h=0.052, dx=0.02, domain=domain)
    rng = np.random.default_rng(2)
    held = []
    for step in range(7):
        before = weakref.ref(calc.results["forces"]) if "forces" in calc.results else None
        kept = None
        if step == 3:
            kept = calc.forces_view(atoms)  # a view held across the next evaluation
            kept_values = kept.copy()
        if step == 4:
            held.append(calc.results["forces"])  # the array itself
            held_values = held[0].copy()
        move = rng.normal(scale=1e-4, size=(len(atoms), 3)) if step != 5 else np.full((len(atoms), 3), 0.01)
        move[:, 2] = 0.0
        builds = calc.nlist.builds if calc.nlist is not None else 0
        for a in (atoms, twin):
            a.positions = a.positions + move
        forces = calc.forces_view(atoms)
        np.testing.assert_array_equal(forces, twin.get_forces())
        rebuilt = calc.nlist.builds > builds
        reused = before is not None and calc.results["forces"] is before()
        # 0: the one-shot evaluation, 1: the list's build, 3 and 4: held, 5: a rebuild
        assert reused == (step in (2, 6)) and rebuilt == (step in (1, 5)), (step, reused, rebuilt)
        forces = None
        if kept is not None:
            np.testing.assert_array_equal(kept, kept_values)
    np.testing.assert_array_equal(held[0], held_values)


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("name", list(__import__("ase_sphrelax.kernels", fromlist=["KERNEL_NAMES"]).KERNEL_NAMES))
def test_wall_forces_are_kernel_w1s_bits(name, dim):
    """Eq. 4.4's force in one numba loop (models.fan._add_wall_forces) equals ``-2 vt Kernel.w1(max(s, 0), h) n``
    bit for bit: outside the wall (s < 0), on it, at the pieces' breaks, just below h, at h and beyond."""
    from ase_sphrelax.models.fan import FanModel, _add_wall_forces

    kernel = get_kernel(name, dim)
    h, v0 = 0.037, 1.3e-4
    breaks = [b * h for b in kernel.breaks[1:-1]]
    s_o = np.concatenate([[-0.5 * h, -1e-300, 0.0, 1e-300, h * (1 - 1e-16), h, 1.5 * h], breaks,
                          np.random.default_rng(0).uniform(-0.2 * h, 1.1 * h, 500)])
    n_oc = np.random.default_rng(1).normal(size=(len(s_o), 3))
    n_oc[:, dim:] = 0.0
    pool = np.random.default_rng(2).permutation(len(s_o) + 7)[: len(s_o)]
    model = FanModel.__new__(FanModel)
    model.kernel, model.h = kernel, h
    f_new = np.full((len(s_o) + 7, 3), 0.25)
    _add_wall_forces(f_new, pool, s_o, n_oc, h, kernel.sigma_1d, -2.0 * v0, *model._w1_pieces())
    f_old = np.full((len(s_o) + 7, 3), 0.25)
    g_o = kernel.w1(np.maximum(s_o, 0.0), h)
    g_o *= -2.0 * v0
    within = s_o < h
    for k in np.flatnonzero(within):
        f_old[pool[k]] += g_o[k] * n_oc[k]
    assert np.array_equal(f_new, f_old)
    assert np.any(f_new != 0.25) and np.all(f_new[pool[~within]] == 0.25)
