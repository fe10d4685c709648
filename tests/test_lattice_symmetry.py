"""classify_lattice: spglib layer/space groups of ideal, supercell and noisy lattices."""
import math

import numpy as np
import pytest
from ase import Atoms
from ase.build import bulk, make_supercell

from ase_sphrelax.analysis import pattern_cell
from ase_sphrelax.analysis.symmetry import (
    LatticeNotFoundError,
    classify_cell,
    classify_lattice,
    layer_group_to_pattern,
    pattern_name_3d,
    space_group_to_bravais,
)

PATTERNS = [("hexagonal", {}), ("square", {}), ("rectangular", {"k": 1.3}), ("diamond", {"k": 2.4}),
            ("diamond", {"k": 1.22}), ("parallelogram", {"k": 1.12, "r": 0.37})]


def sheet(cell2, reps=(5, 3), noise=0.0, seed=0, transform=None):
    full = np.eye(3)
    full[:2, :2] = cell2
    atoms = Atoms("X", positions=[[0.1, 0.2, 0.0]], cell=full, pbc=(True, True, False))
    if transform is not None:
        atoms = make_supercell(atoms, transform)
    atoms = atoms.repeat((reps[0], reps[1], 1))
    rng = np.random.default_rng(seed)
    atoms.positions[:, :2] += rng.normal(0.0, noise, (len(atoms), 2))
    return atoms


@pytest.mark.parametrize("name,params", PATTERNS)
@pytest.mark.parametrize("noise", [0.0, 1e-4, 2e-3])
def test_2d_patterns_ideal_and_noisy(name, params, noise):
    cell, _ = pattern_cell(name, params)
    assert classify_lattice(sheet(cell, noise=noise)) == name


@pytest.mark.parametrize("name,params", PATTERNS)
def test_2d_skewed_supercell_and_rotation(name, params):
    """A sheared, rotated supercell (7 sites) is classified by its primitive lattice."""
    cell, _ = pattern_cell(name, params)
    c, s = math.cos(0.3), math.sin(0.3)
    cell = cell @ np.array([[c, s], [-s, c]])
    atoms = sheet(cell, reps=(1, 1), transform=np.array([[2, 1, 0], [-1, 3, 0], [0, 0, 1]]))
    assert len(atoms) == 7
    label, info = classify_lattice(atoms, return_details=True)
    assert label == name and info["n_basis"] == 1


def test_2d_near_square_rectangle_is_rectangular_at_small_tolerance():
    cell, _ = pattern_cell("rectangular", {"k": 1.02})
    assert classify_lattice(sheet(cell), symprec=1e-4) == "rectangular"
    # a tolerance larger than the distortion sees a square
    assert classify_lattice(sheet(cell, reps=(1, 1)), symprec=0.05) == "square"


def test_2d_not_a_lattice_raises():
    cell, _ = pattern_cell("square")
    with pytest.raises(LatticeNotFoundError, match="not periodic"):
        classify_lattice(sheet(cell, reps=(4, 4), noise=0.3))
    # honeycomb: a lattice with a 2-site basis
    hexc, _ = pattern_cell("hexagonal")
    full = np.eye(3)
    full[:2, :2] = hexc
    honey = Atoms("X2", scaled_positions=[[0, 0, 0], [1 / 3, 1 / 3, 0]], cell=full, pbc=(True, True, False))
    with pytest.raises(LatticeNotFoundError):
        classify_lattice(honey.repeat((3, 3, 1)))
    assert classify_lattice(honey.repeat((3, 3, 1)), max_basis=2) == "hexagonal"


@pytest.mark.parametrize("atoms,expected", [
    (bulk("Cu", "fcc", a=3.6, cubic=True), "cF"),
    (bulk("Fe", "bcc", a=2.9, cubic=True), "cI"),
    (bulk("Po", "sc", a=3.0), "cP"),
    (bulk("In", "bct", a=3.2, c=4.9), "tI"),
    (Atoms("X", cell=[2.0, 2.0, 3.0], pbc=True), "tP"),
    (Atoms("X", cell=[2.0, 2.5, 3.0], pbc=True), "oP"),
    (Atoms("X", cell=[[2.0, 0, 0], [-1.0, math.sqrt(3), 0], [0, 0, 3.0]], pbc=True), "hP"),
    (Atoms("X", cell=[[2.0, 0, 0], [0.3, 2.5, 0], [0.2, 0.4, 3.0]], pbc=True), "aP"),
])
def test_3d_bravais(atoms, expected):
    noisy = atoms.repeat(2)
    noisy.rattle(1e-4, seed=3)
    assert classify_lattice(atoms) == expected
    assert classify_lattice(noisy) == expected


def test_3d_hcp_and_named():
    hcp = bulk("Mg", "hcp", a=3.2).repeat(2)
    hcp.rattle(1e-4, seed=1)
    with pytest.raises(LatticeNotFoundError):
        classify_lattice(hcp)
    assert classify_lattice(hcp, max_basis=2) == "hP"
    assert pattern_name_3d(hcp) == "hcp"
    assert pattern_name_3d(bulk("Cu", "fcc", a=3.6, cubic=True)) == "fcc"
    assert classify_cell(0.5 * np.array([[-1.0, 1, 1], [1, -1, 1], [1, 1, -1]])) == "cI"


def test_group_tables():
    assert layer_group_to_pattern(1, "p1") == "parallelogram"
    assert layer_group_to_pattern(37, "pmmm") == "rectangular"
    assert layer_group_to_pattern(47, "cmmm") == "diamond"
    assert layer_group_to_pattern(61, "p4/mmm") == "square"
    assert layer_group_to_pattern(80, "p6/mmm") == "hexagonal"
    assert space_group_to_bravais(225, "Fm-3m") == "cF"
    assert space_group_to_bravais(166, "R-3m") == "hR"
    assert space_group_to_bravais(12, "C2/m") == "mS"
    with pytest.raises(ValueError):
        layer_group_to_pattern(81, "x")


def test_bad_input():
    with pytest.raises(TypeError):
        classify_lattice("not atoms")
    with pytest.raises(ValueError, match="periodic"):
        classify_lattice(Atoms("X", cell=[1, 1, 1], pbc=False), dim=2)
    with pytest.raises(ValueError, match="symprec"):
        classify_lattice(bulk("Cu"), symprec=-1.0)
    with pytest.raises(ValueError, match="max_basis"):
        classify_lattice(bulk("Cu"), max_basis=0)
