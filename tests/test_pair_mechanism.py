"""The pair mechanism from a new method's point of view.

A toy method defined here, in the test file itself, with no loop of its own: soft-sphere
repulsion with per-particle radii R_i plus a velocity-dependent damping term, as an ASE
calculator. Its conservative forces are checked by finite differences, its sums (energy,
forces with damping, virial) against a brute-force double sum over periodic images.
"""
import itertools

import numba
import numpy as np
import pytest
from ase import Atoms
from ase.calculators.calculator import all_changes
from ase.calculators.fd import calculate_numerical_forces, calculate_numerical_stress

from ase_sphrelax.calculators.base import SPHCalculator
from ase_sphrelax.checks import check_positive
from ase_sphrelax.neighbors import NeighborList
from ase_sphrelax.pairs import Output, PairInteraction


# -- the toy method: physics (one pure function) + a thin calculator ------------------------------
@numba.njit(cache=True, inline="always")
def soft_sphere_pair(a, b, r2, d, k, gamma, radius_s, v_sc):
    """phi = k/2 (1 - r/s)^2 for r < s = R_a + R_b, and damping -gamma (1 - r/s) (v_ab . e) e."""
    s = radius_s[a] + radius_s[b]
    if r2 >= s * s or r2 == 0.0:
        return (0.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    r = np.sqrt(r2)
    w = 1.0 - r / s
    e0, e1, e2 = d[0] / r, d[1] / r, d[2] / r  # unit vector from a to b
    push = k * w / s  # -dphi/dr
    approach = (v_sc[a, 0] - v_sc[b, 0]) * e0 + (v_sc[a, 1] - v_sc[b, 1]) * e1 + (v_sc[a, 2] - v_sc[b, 2]) * e2
    g = -push - gamma * w * approach  # force on a along e
    half = 0.25 * k * w * w
    virial = (-push * r * e0 * e0, -push * r * e1 * e1, -push * r * e2 * e2,
              -push * r * e1 * e2, -push * r * e0 * e2, -push * r * e0 * e1)
    return (half, g * e0, g * e1, g * e2), (half, -g * e0, -g * e1, -g * e2), virial


SOFT_SPHERES = PairInteraction(soft_sphere_pair, dict(energies=Output(()), forces=Output((3,)),
                                                      virial=Output((6,), per_point=False)),
                               params=("k", "gamma"), inputs=("radius_s", "v_sc"))


class SoftSphereCalculator(SPHCalculator):
    implemented_properties = ["energy", "free_energy", "energies", "forces", "stress"]
    default_parameters = dict(k=1.0, gamma=0.0, dim=None, skin=0.1)
    velocity_dependent = True

    def _validate_parameters(self):
        super()._validate_parameters()
        check_positive("k", self.parameters.k)

    def cutoff(self, atoms, dim):
        radius_p = atoms.get_array("radius")
        return radius_p + radius_p.max(), self.parameters.skin

    def evaluate(self, state, properties):
        p, atoms = self.parameters, state.atoms
        radius_p = atoms.get_array("radius")
        v_pc = state.v_pc if state.v_pc is not None else np.zeros_like(state.r_pc)
        out = SOFT_SPHERES.compute(state.nlist, state.r_pc, params=dict(k=p.k, gamma=p.gamma),
                                   inputs=dict(radius_s=radius_p, v_sc=v_pc),
                                   reach=2.0 * radius_p.max())
        results = dict(energy=out.energies.sum(), energies=out.energies, forces=out.forces)
        if atoms.cell.rank == 3 and atoms.pbc.all():
            v = out.virial
            results["stress"] = np.array([v[0], v[1], v[2], v[3], v[4], v[5]]) / atoms.get_volume()
        return results


# -- references --------------------------------------------------------------------------------------
def brute_force(atoms, k, gamma):
    """O(N^2 images) energy, forces and virial of the toy method."""
    r, v, radius = atoms.positions, atoms.get_velocities(), atoms.get_array("radius")
    cell = atoms.cell.array
    span = [range(-2, 3) if p else range(1) for p in atoms.pbc]
    energy, forces, virial = 0.0, np.zeros_like(r), np.zeros((3, 3))
    for shift in itertools.product(*span):
        t = np.array(shift) @ cell
        for i in range(len(r)):
            for j in range(len(r)):
                if i == j and not any(shift):
                    continue
                dvec = r[j] + t - r[i]
                dist, s = np.linalg.norm(dvec), radius[i] + radius[j]
                if dist >= s:
                    continue
                e, w = dvec / dist, 1.0 - dist / s
                energy += 0.25 * k * w * w  # each ordered pair: half the pair energy
                forces[i] += (-k * w / s - gamma * w * np.dot(v[i] - v[j], e)) * e
                virial += 0.5 * (-k * w / s) * dist * np.outer(e, e)
    return energy, forces, virial


def make_atoms(seed, periodic, n=40, box=3.0):
    rng = np.random.default_rng(seed)
    atoms = Atoms("X" * n, positions=rng.uniform(0, box, (n, 3)), cell=[box] * 3, pbc=periodic)
    atoms.set_array("radius", rng.uniform(0.3, 0.6, n))
    return atoms


@pytest.mark.parametrize("periodic", [True, False])
def test_toy_method_sums_match_brute_force(periodic):
    atoms = make_atoms(1, periodic)
    atoms.set_velocities(np.random.default_rng(2).normal(size=(len(atoms), 3)))
    calc = SoftSphereCalculator(k=2.0, gamma=0.7)
    e_ref, f_ref, vir_ref = brute_force(atoms, 2.0, 0.7)
    for _ in range(2):  # first evaluation: fused bin scan; second: stored Verlet list
        calc.calculate(atoms, ["energy", "forces"], all_changes)
        assert calc.results["energy"] == pytest.approx(e_ref, rel=1e-12)
        np.testing.assert_allclose(calc.results["forces"], f_ref, atol=1e-12 * np.abs(f_ref).max())
    if periodic:
        stress = calc.get_stress(atoms)
        np.testing.assert_allclose(stress, vir_ref.flat[[0, 4, 8, 5, 2, 1]] / atoms.get_volume(), atol=1e-12)


@pytest.mark.parametrize("periodic", [True, False])
def test_toy_method_conservative_forces_and_stress_match_finite_differences(periodic):
    atoms = make_atoms(3, periodic)
    atoms.calc = SoftSphereCalculator(k=2.0, gamma=0.0)
    forces = atoms.get_forces()
    np.testing.assert_allclose(forces, calculate_numerical_forces(atoms, eps=1e-6), atol=1e-7)
    if periodic:
        np.testing.assert_allclose(atoms.get_stress(), calculate_numerical_stress(atoms, eps=1e-6), atol=1e-7)


def test_velocity_dependent_forces_are_not_served_from_the_cache():
    atoms = make_atoms(4, True)
    atoms.calc = SoftSphereCalculator(k=1.0, gamma=1.0)
    f_rest = atoms.get_forces()
    atoms.set_velocities(np.random.default_rng(5).normal(size=(len(atoms), 3)))
    f_moving = atoms.get_forces()
    assert np.abs(f_moving - f_rest).max() > 1e-3
    np.testing.assert_allclose(f_moving, brute_force(atoms, 1.0, 1.0)[1], atol=1e-12)


@numba.njit(cache=True, inline="always")
def count_within(a, b, r2, d, radius_s):
    """Gather-style: a counts the partners within its own radius R_a (and weighs them by r^2)."""
    if r2 < radius_s[a] ** 2:
        return (1.0, r2), (r2,)
    return (0.0, 0.0), (0.0,)


COUNTS = PairInteraction(count_within, dict(count=Output(()), r2_sum=Output(()), total=Output((), per_point=False)),
                         inputs=("radius_s",), symmetric=False)


def brute_counts(r_pc, cell, pbc, radius_p):
    count = np.zeros(len(r_pc))
    span = [range(-2, 3) if p else range(1) for p in pbc]
    for shift in itertools.product(*span):
        dist = np.linalg.norm(r_pc[None, :, :] + np.array(shift) @ cell - r_pc[:, None, :], axis=2)
        if not any(shift):
            np.fill_diagonal(dist, np.inf)
        count += (dist < radius_p[:, None]).sum(axis=1)
    return count


def test_gather_interaction_uses_each_points_own_radius():
    rng = np.random.default_rng(6)
    r_pc = rng.uniform(0, 4, (200, 3))
    radius_p = rng.uniform(0.3, 1.0, 200)
    cell, pbc = np.diag([4.0] * 3), [True, True, False]
    nlist = NeighborList(radius_p, skin=0.2)
    nlist.update(r_pc, cell, pbc)
    out = COUNTS.compute(nlist, r_pc, inputs=dict(radius_s=radius_p))
    np.testing.assert_array_equal(out.count, brute_counts(r_pc, cell, pbc, radius_p))
    assert out.total[0] == pytest.approx(out.r2_sum.sum(), rel=1e-12)


def test_cutoffs_growing_within_the_skin_reuse_the_list_and_beyond_it_rebuild():
    rng = np.random.default_rng(7)
    r_pc = rng.uniform(0, 4, (300, 3))
    cell, pbc = np.diag([4.0] * 3), [True] * 3
    radius_p = rng.uniform(0.4, 0.8, 300)
    nlist = NeighborList(radius_p, skin=0.2)
    assert nlist.update(r_pc, cell, pbc)
    grown = radius_p + 0.1
    moved = r_pc + rng.uniform(-0.02, 0.02, r_pc.shape)  # 2 * 0.035 + 0.1 <= skin
    assert not nlist.update(moved, cell, pbc, cutoff=grown)
    np.testing.assert_array_equal(COUNTS.compute(nlist, moved, inputs=dict(radius_s=grown)).count,
                                  brute_counts(moved, cell, pbc, grown))
    assert nlist.builds == 1
    too_far = radius_p + 0.25
    assert nlist.update(moved, cell, pbc, cutoff=too_far)
    assert nlist.builds == 2
    np.testing.assert_array_equal(COUNTS.compute(nlist, moved, inputs=dict(radius_s=too_far)).count,
                                  brute_counts(moved, cell, pbc, too_far))


def test_points_of_higher_dimension_walk_a_stored_list():
    """dim=D interactions take D-component separations (point sets beyond ASE's 3 axes)."""
    @numba.njit(inline="always")
    def squared(a, b, r2, d):
        return (r2, d[4]), (r2, -d[4]), ()

    interaction = PairInteraction(squared, dict(r2=Output(()), d4=Output(())), dim=5)

    class Pairs:  # the smallest neighbour object: all pairs, no ghosts
        def __init__(self, x):
            n = len(x)
            self.x = x
            self.pair_start = np.concatenate([[0], np.cumsum(np.arange(n - 1, -1, -1))]).astype(np.int64)
            self.pair_j = np.concatenate([np.arange(a + 1, n) for a in range(n)]).astype(np.int32)
            self.max_cutoff = np.inf

        def extend(self, positions):
            return positions

        def gather(self, values, slot=0):
            return values

        def loop_arrays(self):
            return "list", (self.pair_start, self.pair_j)

        def fold_threads(self, bufs):
            return [buf.sum(axis=0) for buf in bufs]

    x = np.random.default_rng(8).normal(size=(30, 5))
    out = interaction.compute(Pairs(x), x, reach=1e300)
    diff = x[None, :, :] - x[:, None, :]
    np.testing.assert_allclose(out.r2, (diff**2).sum(axis=2).sum(axis=1), rtol=1e-12)
    np.testing.assert_allclose(out.d4, diff[:, :, 4].sum(axis=1), atol=1e-12)


def test_every_sum_accepts_the_list_in_both_states():
    """kernel_sums and pair_potential_sums take a NeighborList one-shot (first evaluation) or stored."""
    from ase_sphrelax.kernel_sums import kernel_sums, pair_potential_sums
    from ase_sphrelax.kernels import get_kernel

    rng = np.random.default_rng(10)
    r_pc = np.zeros((150, 3))
    r_pc[:, :2] = rng.uniform(0, 5, (150, 2))
    cell, pbc, kernel = np.diag([5.0, 5.0, 1.0]), [True, True, False], get_kernel("wendland_c2", 2)
    results = []
    for store in (False, True):
        nlist = NeighborList(1.3, skin=0.2)
        nlist.update(r_pc, cell, pbc, store=store)
        assert nlist.stored == store
        sums = kernel_sums(nlist, r_pc, 1.3, kernel)
        e_p, f_pc, vir = pair_potential_sums(nlist, r_pc, 1.3, 1.0, kernel, want_virial=True)
        results.append((sums.w_p, sums.grad_pc, e_p, f_pc, vir))
    for one_shot, listed in zip(*results):
        np.testing.assert_allclose(listed, one_shot, rtol=1e-12, atol=1e-14)


def test_outputs_are_written_into_given_arrays_in_both_states_and_folds():
    """``compute(..., out=)``: a per-point output is written into the given array (returned itself, equal to a fresh
    result bit for bit; whatever it held is overwritten), on a periodic list with ghosts, one-shot or stored, and
    through the stacked fold of a neighbour set without forward pairs; a wrong array is a one-line ValueError."""
    from ase_sphrelax.kernel_sums import KERNEL_SUMS, pair_potential_sums
    from ase_sphrelax.kernels import get_kernel
    from ase_sphrelax.tree_neighbors import TreeNeighborList

    rng = np.random.default_rng(12)
    r_pc = np.zeros((150, 3))
    r_pc[:, :2] = rng.uniform(0, 5, (150, 2))
    cell, pbc, kernel = np.diag([5.0, 5.0, 1.0]), [True, True, False], get_kernel("wendland_c2", 2)
    for store in (False, True):
        nlist = NeighborList(1.3, skin=0.2)
        nlist.update(r_pc, cell, pbc, store=store)
        fresh = KERNEL_SUMS.compute(nlist, r_pc, dict(inv_h=1 / 1.3), kernel=kernel)
        grad = np.full((150, 3), np.nan)
        given = KERNEL_SUMS.compute(nlist, r_pc, dict(inv_h=1 / 1.3), kernel=kernel, out=dict(grad=grad))
        assert given.grad is grad
        np.testing.assert_array_equal(grad, fresh.grad)
        np.testing.assert_array_equal(given.w, fresh.w)
        forces = np.full((150, 3), np.nan)
        _, f_pc, _ = pair_potential_sums(nlist, r_pc, 1.3, 1.0, kernel, want_energy=False, forces_out=forces)
        assert f_pc is forces and np.all(np.isfinite(forces))
    tree = TreeNeighborList(1.3)
    tree.update(np.ascontiguousarray(r_pc[:, :2]))
    assert not getattr(tree, "forward_pairs", False)  # the stacked buffers' fold
    x2 = np.ascontiguousarray(r_pc[:, :2])
    fresh = KERNEL_SUMS_2D.compute(tree, x2, dict(inv_h=1 / 1.3))
    w = np.full(150, np.nan)
    given = KERNEL_SUMS_2D.compute(tree, x2, dict(inv_h=1 / 1.3), out=dict(w=w))
    assert given.w is w
    np.testing.assert_array_equal(w, fresh.w)
    nlist = NeighborList(1.3, skin=0.2)
    nlist.update(r_pc, cell, pbc)
    for bad, match in [(dict(grad=np.zeros((150, 2))), "shape"), (dict(grad=np.zeros((3, 150)).T), "C-contiguous"),
                       (dict(grad=np.zeros((150, 3), dtype=np.float32)), "float64"),
                       (dict(virial=np.zeros(150)), "per-point outputs")]:
        with pytest.raises(ValueError, match=match):
            KERNEL_SUMS.compute(nlist, r_pc, dict(inv_h=1 / 1.3), kernel=kernel, out=bad)


@numba.njit(cache=True, inline="always")
def _count_pair_2d(a, b, r2, d, inv_h):
    w = max(1.0 - np.sqrt(r2) * inv_h, 0.0)
    return (w,), (w,), ()


KERNEL_SUMS_2D = PairInteraction(_count_pair_2d, dict(w=Output(())), params=("inv_h",), dim=2)


def test_gather_copies_values_to_ghosts_without_image_shifts():
    rng = np.random.default_rng(11)
    r_pc = rng.uniform(0, 2, (20, 3))
    nlist = NeighborList(0.9)
    nlist.update(r_pc, np.diag([2.0] * 3), [True] * 3)
    v_pc = rng.normal(size=(20, 3))
    assert nlist.n_extended > 20  # ghosts exist
    np.testing.assert_array_equal(nlist.gather(v_pc), v_pc[nlist.src_s])
    x_sc = nlist.extend(r_pc)
    assert np.abs(x_sc - r_pc[nlist.src_s]).max() > 1.0  # positions do move with their image
    with pytest.raises(ValueError, match="one row per particle"):
        nlist.gather(v_pc[:5])


def test_pair_data_are_checked_by_name():
    """A misspelt, missing or extra name is a one-line error naming it, at construction and at compute."""
    outputs = dict(energies=Output(()), forces=Output((3,)), virial=Output((6,), per_point=False))
    with pytest.raises(ValueError, match="has no argument 'gama'"):
        PairInteraction(soft_sphere_pair, outputs, params=("k", "gama"), inputs=("radius_s", "v_sc"))
    with pytest.raises(ValueError, match="argument 'v_sc' is declared in none"):
        PairInteraction(soft_sphere_pair, outputs, params=("k", "gamma"), inputs=("radius_s",))
    with pytest.raises(ValueError, match="'k' is declared more than once"):
        PairInteraction(soft_sphere_pair, outputs, params=("k", "gamma"), inputs=("radius_s", "v_sc", "k"))
    atoms = make_atoms(1, True)
    nlist = NeighborList(1.2, skin=0.1)
    nlist.update(atoms.positions, atoms.cell.array, atoms.pbc)
    inputs = dict(radius_s=atoms.get_array("radius"), v_sc=np.zeros((len(atoms), 3)))
    with pytest.raises(ValueError, match="needs 'gamma'"):
        SOFT_SPHERES.compute(nlist, atoms.positions, params=dict(k=1.0), inputs=inputs)
    with pytest.raises(ValueError, match="has no param 'gama'"):
        SOFT_SPHERES.compute(nlist, atoms.positions, params=dict(k=1.0, gamma=0.0, gama=0.0), inputs=inputs)
    with pytest.raises(TypeError, match="dict by name"):
        SOFT_SPHERES.compute(nlist, atoms.positions, params=(1.0, 0.0), inputs=inputs)
    out = SOFT_SPHERES.compute(nlist, atoms.positions, params=dict(gamma=0.0, k=2.0), inputs=inputs)  # any order
    assert out.energies.sum() == pytest.approx(brute_force(atoms, 2.0, 0.0)[0], rel=1e-12)


def test_kernel_placeholders_need_a_kernel_and_constants_give_variants():
    from ase_sphrelax.kernel_sums import PAIR_POTENTIAL, PAIR_POTENTIAL_VIRIAL
    from ase_sphrelax.kernels import get_kernel

    atoms = make_atoms(2, True)
    nlist = NeighborList(1.0, skin=0.1)
    nlist.update(atoms.positions, atoms.cell.array, atoms.pbc)
    with pytest.raises(ValueError, match="kernel"):
        PAIR_POTENTIAL.compute(nlist, atoms.positions, params=dict(inv_h=1.0, scale=1.0))
    results = [interaction.compute(nlist, atoms.positions, params=dict(inv_h=1.0, scale=1.0),
                                   kernel=get_kernel(name, 3))
               for interaction in (PAIR_POTENTIAL, PAIR_POTENTIAL_VIRIAL) for name in ("wendland_c2", "cubic_spline")]
    # the virial flag changes nothing else: the same forces to round-off (the two compiled loops may order the
    # vectorised sums differently: on AVX-512 5 of 120 components differed in the last bit)
    scale = np.abs(results[0].forces).max()
    np.testing.assert_allclose(results[2].forces, results[0].forces, rtol=0, atol=1e-14 * scale)
    assert np.abs(results[0].forces - results[1].forces).max() > 1e-3  # each kernel its own loop
    assert "virial" in results[2] and "virial" not in results[0]


@numba.njit(cache=True, inline="always")
def planar_probe(a, b, r2, d):
    """A spatial force g d and a non-spatial 3-vector (1, r2, d2 + 1) per pair."""
    g = 1.0 - r2
    return (g * d[0], g * d[1], g * d[2], 1.0, r2, d[2] + 1.0), (-g * d[0], -g * d[1], -g * d[2], 1.0, r2,
                                                                 d[2] + 1.0), ()


PLANAR_PROBE = PairInteraction(planar_probe, dict(force=Output((3,), spatial=True), other=Output((3,))))


@pytest.mark.parametrize("periodic", [True, False])
def test_planar_loops_equal_the_3d_loops_for_points_at_z_zero(periodic):
    """compute(..., planar=True) reads x, y only and skips the z term of spatial outputs: for points at z = 0
    its sums equal the 3D loop's (list walk and fused build), a non-spatial vector keeps all its components."""
    rng = np.random.default_rng(4)
    r_pc = np.zeros((300, 3))
    r_pc[:, :2] = rng.uniform(0, 4, (300, 2))
    r_pc[1] = r_pc[0]  # a coincident pair
    cell, pbc = np.diag([4.0, 4.0, 1.0]), [periodic, periodic, False]
    for store in (False, True):
        outs = []
        for planar in (False, True):
            nlist = NeighborList(0.7, skin=0.1)
            nlist.update(r_pc, cell, pbc, store=store)
            outs.append(PLANAR_PROBE.compute(nlist, r_pc, reach=0.7, planar=planar))
            if store:  # the stored list walked (the first sum fused the build)
                outs[-1] = PLANAR_PROBE.compute(nlist, r_pc, reach=0.7, planar=planar)
        full, flat = outs
        np.testing.assert_allclose(flat.force, full.force, rtol=1e-13, atol=1e-15)
        assert not flat.force[:, 2].any()
        np.testing.assert_allclose(flat.other, full.other, rtol=1e-13)
        assert flat.other[:, 2].min() >= 1.0  # d[2] + 1 summed over each point's pairs: accumulated
