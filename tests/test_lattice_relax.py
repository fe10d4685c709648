"""Variable-cell relaxation at constant area reproduces the predicted pattern (issue item 5).

The relaxed arrangement, classified by spglib, must be the symmetry class of
the best lattice (``predict_pattern(..., convention="bravais")``) and its
characteristic volume (Eq. 5.2, from the relaxed energy) must equal the
global maximum of ``v_c`` to 1e-4.
"""
import numpy as np
import pytest
from ase import Atoms

from ase_sphrelax import FanCalculator
from ase_sphrelax.analysis.cell_filter import ConstantMeasureCellFilter
from ase_sphrelax.analysis import characteristic_volume, characteristic_volume_of_atoms, predict_pattern
from ase_sphrelax.analysis.patterns import lattice_supercell, relax_lattice
from ase_sphrelax.analysis.symmetry import classify_lattice, pattern_name_3d

H_VALUES = (1.6, 2.0, 2.15, 2.6, 3.4)


def check_relaxed(atoms, h):
    expected = predict_pattern(h, convention="bravais")
    v_best = characteristic_volume("parallelogram", h, convention="bravais")[0]
    assert classify_lattice(atoms) == expected
    assert atoms.info["v_c"] == pytest.approx(v_best, abs=1e-4)
    # v_c from the energy (Eq. 5.2) equals the direct lattice sum of the relaxed positions
    assert characteristic_volume_of_atoms(atoms, h) == pytest.approx(atoms.info["v_c"], abs=1e-9)
    area = abs(np.linalg.det(atoms.cell.array[:2, :2]))
    assert area == pytest.approx(len(atoms), rel=1e-12)


@pytest.mark.parametrize("h", H_VALUES)
@pytest.mark.parametrize("n_atoms", [1, 2])
def test_relax_small_cells_from_random_positions(h, n_atoms):
    atoms = relax_lattice(h, n_atoms, seed=7, n_starts=6, lattice_starts=False, fmax=1e-5)
    check_relaxed(atoms, h)


@pytest.mark.slow
@pytest.mark.parametrize("h", H_VALUES)
def test_relax_four_particles_from_random_positions(h):
    atoms = relax_lattice(h, 4, seed=3, n_starts=4, lattice_starts=False, fmax=1e-5)
    check_relaxed(atoms, h)


@pytest.mark.slow
@pytest.mark.parametrize("h", H_VALUES)
def test_relax_64_particles(h):
    """64 particles: perturbed candidate supercells (noise 0.05 dx) plus one random start."""
    atoms = relax_lattice(h, 64, seed=1, n_starts=1, fmax=1e-5, steps=1500)
    check_relaxed(atoms, h)


def test_relax_3d_two_particles_h2():
    """3D at h = 2.0: the simple cubic lattice wins (Fan Sec. 5.2, last paragraph)."""
    atoms = relax_lattice(2.0, 2, dim=3, seed=0, n_starts=2, fmax=1e-5)
    assert pattern_name_3d(atoms) == "sc"
    assert atoms.info["v_c"] == pytest.approx(characteristic_volume("sc", 2.0, dim=3)[0], abs=1e-4)
    assert atoms.get_volume() == pytest.approx(2.0, rel=1e-12)


@pytest.mark.parametrize("dim", [2, 3])
def test_constant_measure_filter_area_and_gradient(dim):
    """The filter keeps the area/volume exactly and its forces are -dE/d(generalised coordinates)."""
    rng = np.random.default_rng(1)
    n = 6
    if dim == 2:
        cell = np.array([[2.3, 0.4, 0], [0.2, 2.9, 0], [0, 0, 1.0]])
        pos = np.c_[rng.random((n, 2)) @ cell[:2, :2], np.zeros(n)]
        pbc = (True, True, False)
    else:
        cell = np.array([[1.9, 0.2, 0.1], [0.1, 1.7, 0.3], [0.2, 0.1, 2.0]])
        pos = rng.random((n, 3)) @ cell
        pbc = True
    atoms = Atoms(f"X{n}", positions=pos, cell=cell, pbc=pbc)
    atoms.calc = FanCalculator(h=2.6, dim=dim)
    filt = ConstantMeasureCellFilter(atoms, dim=dim)
    x0 = filt.get_positions()
    assert x0.shape == (len(filt), 3)
    x0[n:] += rng.normal(0.0, 3.0, x0[n:].shape)  # a large shape change
    x0[n:, 2] = 0.0
    filt.set_positions(x0)
    measure = abs(np.linalg.det(atoms.cell.array[:dim, :dim]))
    assert measure == pytest.approx(abs(np.linalg.det(cell[:dim, :dim])), rel=1e-12)
    assert np.allclose(filt.get_positions(), x0, atol=1e-12)
    if dim == 2:
        assert np.allclose(atoms.cell.array[2], [0, 0, 1]) and np.allclose(atoms.positions[:, 2], 0)
    g = filt.get_forces()
    e0 = filt.get_potential_energy()
    eps = 1e-6
    for mask in ("all", "cell"):
        d = rng.normal(0.0, 1.0, x0.shape)
        d[n:, 2] = 0.0
        if dim == 2:
            d[:, 2] = 0.0
        if mask == "cell":
            d[:n] = 0.0
        filt.set_positions(x0 + eps * d)
        ep = filt.get_potential_energy()
        filt.set_positions(x0 - eps * d)
        em = filt.get_potential_energy()
        assert (ep - em) / (2 * eps) == pytest.approx(-(g * d).sum(), rel=1e-6, abs=1e-10)
    filt.set_positions(x0)
    assert filt.get_potential_energy() == pytest.approx(e0, rel=1e-14)


def test_ase_frechet_filter_loses_area_but_ours_does_not():
    """FACTS.md: FrechetCellFilter(constant_volume=True) does not keep a 2D area; this filter does."""
    from ase.filters import FrechetCellFilter
    from ase.optimize import FIRE

    start = lattice_supercell("rectangular", 16, {"k": 1.6})
    start.positions[:, :2] += np.random.default_rng(0).normal(0.0, 0.05, (16, 2))
    areas = {}
    for name in ("ase", "ours"):
        atoms = start.copy()
        atoms.calc = FanCalculator(h=2.6, dim=2)
        filt = FrechetCellFilter(atoms, constant_volume=True) if name == "ase" else \
            ConstantMeasureCellFilter(atoms, dim=2)
        FIRE(filt, logfile=None).run(fmax=1e-3, steps=15)
        areas[name] = abs(np.linalg.det(atoms.cell.array[:2, :2]))
    assert areas["ours"] == pytest.approx(16.0, rel=1e-12)
    assert abs(areas["ase"] - 16.0) > 1e-3


def test_relax_lattice_bad_input():
    with pytest.raises(ValueError, match="n_atoms"):
        relax_lattice(2.6, 0)
    with pytest.raises(ValueError, match="optimizer"):
        relax_lattice(2.6, 4, optimizer="sgd")
    with pytest.raises(ValueError, match="dim"):
        relax_lattice(2.6, 4, dim=1)
    with pytest.raises(ValueError):
        relax_lattice(2.6, 4, n_starts=0, lattice_starts=False)
