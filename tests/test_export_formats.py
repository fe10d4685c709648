"""Exports to SWIFT, GADGET-4 HDF5 and VTU (ase_sphrelax.io, sphrelax export), read back by readers we did not
write: ``swiftsimio.load``, ``h5py`` and ``pynbody``, ``meshio.read``.

Every array and the box are compared to 1e-12 (the files store double precision). The expected box-code
coordinates are computed here from the documented rule (shift by ``atoms.info["origin"]`` and wrap along periodic
axes; bounded axes shifted by the lower corner minus the largest support radius), not by the writer's helper.
"""
from __future__ import annotations

import numpy as np
import pytest
from ase import Atoms
from ase.io import read, write
from hypothesis import given, settings
from hypothesis import strategies as st

from ase_sphrelax.io import box_frame, collect, write_gadget, write_swift, write_vtu
from ase_sphrelax.io.swift import SWIFT_KERNEL_GAMMA, swift_smoothing_length

swiftsimio = pytest.importorskip("swiftsimio")
h5py = pytest.importorskip("h5py")
meshio = pytest.importorskip("meshio")

TOL = 1e-12


def alaric_like(dim, periodic, n=24, seed=0, origin=True):
    """Particles as ``sphrelax density`` writes them: per-particle masses, support ``h``, ``rho``, momenta.

    Periodic 1D: positions in [-1, 1) with the cell [0, 2) and ``info["origin"] = [-1]`` (the density output).
    Periodic 2D/3D: a cell of sides 2 (and 1, 0.5: powers of 2 for GADGET) with the same kind of origin.
    Bounded: a cloud around 0, cell zero, not periodic.
    """
    rng = np.random.default_rng(seed)
    sides = np.array([2.0, 1.0, 0.5])[:dim]
    r_pc = np.zeros((n, 3))
    if periodic:
        lo = -sides / 2 if origin else np.zeros(dim)
        r_pc[:, :dim] = lo + rng.uniform(size=(n, dim)) * sides
        cell = np.diag(np.concatenate([sides, np.zeros(3 - dim)]))
        pbc = [k < dim for k in range(3)]
    else:
        r_pc[:, :dim] = rng.normal(size=(n, dim))
        cell = np.zeros((3, 3))
        pbc = [False] * 3
    atoms = Atoms(numbers=np.zeros(n, int), positions=r_pc, cell=cell, pbc=pbc)
    atoms.set_masses(rng.uniform(0.5, 1.5, n))
    atoms.new_array("h", rng.uniform(0.1, 0.3, n))
    atoms.new_array("rho", rng.uniform(0.8, 1.2, n))
    atoms.new_array("target", rng.uniform(0.8, 1.2, n))
    p_pc = np.zeros((n, 3))
    p_pc[:, :dim] = rng.normal(size=(n, dim))
    atoms.set_momenta(p_pc)
    if periodic and origin:
        atoms.info["origin"] = (-sides / 2).tolist()
    return atoms


def expected_box_positions(atoms, dim):
    """The documented frame, computed independently of ``box_frame``."""
    r_pc = atoms.positions.copy()
    origin = np.zeros(3)
    origin[:dim] = atoms.info.get("origin", np.zeros(dim))
    r_pc -= origin
    box = np.ones(3)
    for k in range(dim):
        if atoms.pbc[k]:
            box[k] = atoms.cell[k, k]
            r_pc[:, k] = np.mod(r_pc[:, k], box[k])
        else:
            pad = atoms.arrays["h"].max()
            box[k] = np.ptp(r_pc[:, k]) + 2 * pad
            r_pc[:, k] -= r_pc[:, k].min() - pad
    return r_pc, box


CASES = [(dim, periodic) for dim in (1, 2, 3) for periodic in (True, False)]


@pytest.mark.parametrize("dim, periodic", CASES)
def test_swift_round_trip_through_swiftsimio_load(tmp_path, dim, periodic):
    atoms = alaric_like(dim, periodic)
    path = write_swift(atoms, tmp_path / "ics.hdf5", cs2=1.0, kernel="cubic-spline")
    data = swiftsimio.load(str(path))
    r_pc, box = expected_box_positions(atoms, dim)
    np.testing.assert_allclose(data.gas.coordinates.v, r_pc, rtol=0, atol=TOL)
    np.testing.assert_allclose(data.metadata.boxsize.v, box, rtol=TOL)
    np.testing.assert_allclose(data.gas.velocities.v, atoms.get_velocities(), rtol=0, atol=TOL)
    np.testing.assert_allclose(data.gas.masses.v, atoms.get_masses(), rtol=TOL)
    gamma_k = SWIFT_KERNEL_GAMMA["cubic-spline"][dim]
    np.testing.assert_allclose(data.gas.smoothing_lengths.v * gamma_k, atoms.arrays["h"], rtol=TOL)
    np.testing.assert_allclose(data.gas.densities.v, atoms.arrays["rho"], rtol=TOL)
    np.testing.assert_allclose(data.gas.internal_energies.v, 1.0 / (5.0 / 3.0 - 1.0), rtol=TOL)
    np.testing.assert_array_equal(data.gas.particle_ids.v, np.arange(1, len(atoms) + 1))
    assert np.all(data.gas.coordinates.v >= 0) and np.all(data.gas.coordinates.v < box)
    with h5py.File(path) as handle:
        header = handle["Header"].attrs
        assert int(np.ravel(header["Dimension"])[0]) == dim
        assert np.all(header["MassTable"] == 0)  # per-particle masses, not one mass per type
        assert int(handle["RuntimePars"].attrs["PeriodicBoundariesOn"]) == int(periodic)
        assert "SmoothingLength" in handle["PartType0"] and "InternalEnergy" in handle["PartType0"]
        assert handle["PartType0/Coordinates"].dtype == np.float64
    assert str(data.gas.coordinates.units) == "cm" and str(data.gas.masses.units) == "g"


@pytest.mark.filterwarnings("ignore:No unit information found:RuntimeWarning")
@pytest.mark.filterwarnings("ignore:Unable to infer units:UserWarning")
@pytest.mark.parametrize("dim, periodic", CASES)
def test_gadget_round_trip_through_h5py_and_pynbody(tmp_path, dim, periodic):
    pynbody = pytest.importorskip("pynbody")
    atoms = alaric_like(dim, periodic)
    path = write_gadget(atoms, tmp_path / "ics.hdf5", cs2=2.0, gamma=1.4)
    r_pc, box = expected_box_positions(atoms, dim)
    with h5py.File(path) as handle:
        header = handle["Header"].attrs
        for name in ("NumPart_ThisFile", "NumPart_Total", "NumPart_Total_HighWord", "MassTable", "Time", "Redshift",
                     "BoxSize", "NumFilesPerSnapshot", "Flag_DoublePrecision", "Flag_Sfr", "Flag_Cooling"):
            assert name in header
        assert header["NumPart_ThisFile"][0] == header["NumPart_Total"][0] == len(atoms)
        assert header["BoxSize"] == pytest.approx(box[:dim].max(), rel=TOL)
        np.testing.assert_allclose(header["ase_sphrelax_box"], box, rtol=TOL)
        assert header["ase_sphrelax_dim"] == dim and np.all(header["MassTable"] == 0)
        gas = handle["PartType0"]
        np.testing.assert_allclose(gas["Coordinates"][:], r_pc, rtol=0, atol=TOL)
        np.testing.assert_allclose(gas["SmoothingLength"][:], atoms.arrays["h"], rtol=TOL)  # GADGET: the support
    snap = pynbody.load(str(path))
    gas = snap.gas
    assert len(gas) == len(atoms)
    np.testing.assert_allclose(np.asarray(gas["pos"]), r_pc, rtol=0, atol=TOL)
    np.testing.assert_allclose(np.asarray(gas["vel"]), atoms.get_velocities(), rtol=0, atol=TOL)
    np.testing.assert_allclose(np.asarray(gas["mass"]), atoms.get_masses(), rtol=TOL)
    np.testing.assert_allclose(np.asarray(gas["smooth"]), atoms.arrays["h"], rtol=TOL)
    np.testing.assert_allclose(np.asarray(gas["rho"]), atoms.arrays["rho"], rtol=TOL)
    np.testing.assert_allclose(np.asarray(gas["u"]), 2.0 / 0.4, rtol=TOL)
    np.testing.assert_array_equal(np.asarray(gas["iord"]), np.arange(1, len(atoms) + 1))
    length_unit = gas["pos"].units  # pynbody's default GADGET units: the same unit for the box and the positions
    boxsize = snap.properties["boxsize"].ratio(length_unit, **snap.conversion_context())
    assert boxsize == pytest.approx(box[:dim].max(), rel=TOL)


@pytest.mark.parametrize("dim, periodic", CASES)
def test_vtu_round_trip_through_meshio_read(tmp_path, dim, periodic):
    atoms = alaric_like(dim, periodic)
    path = write_vtu(atoms, tmp_path / "p.vtu", cs2=1.0)
    mesh = meshio.read(path)
    np.testing.assert_allclose(mesh.points, atoms.positions, rtol=0, atol=TOL)  # the atoms' own frame
    data = mesh.point_data
    np.testing.assert_allclose(data["velocity"], atoms.get_velocities(), rtol=0, atol=TOL)
    np.testing.assert_allclose(data["mass"], atoms.get_masses(), rtol=TOL)
    np.testing.assert_allclose(data["support_radius"], atoms.arrays["h"], rtol=TOL)
    np.testing.assert_allclose(data["density"], atoms.arrays["rho"], rtol=TOL)
    np.testing.assert_allclose(data["target"], atoms.arrays["target"], rtol=TOL)
    np.testing.assert_allclose(data["internal_energy"], 1.5, rtol=TOL)
    np.testing.assert_array_equal(data["type"], 1)
    fields = mesh.field_data
    np.testing.assert_allclose(fields["cell"].reshape(3, 3), atoms.cell.array, rtol=0, atol=TOL)
    np.testing.assert_array_equal(fields["pbc"], atoms.pbc.astype(int))
    assert int(fields["dim"][0]) == dim
    assert [cells.type for cells in mesh.cells] == ["vertex"] and len(mesh.cells[0].data) == len(atoms)


def test_vtu_of_fan_output_without_masses_writes_the_rest(tmp_path):
    atoms = alaric_like(2, True, origin=False)
    del atoms.arrays["masses"], atoms.arrays["momenta"]
    atoms.new_array("type", np.where(np.arange(len(atoms)) < 5, 2, 1))
    mesh = meshio.read(write_vtu(atoms, tmp_path / "fan.vtu"))
    assert "mass" not in mesh.point_data and "internal_energy" not in mesh.point_data
    np.testing.assert_array_equal(mesh.point_data["type"], atoms.arrays["type"])
    np.testing.assert_array_equal(mesh.point_data["velocity"], 0.0)


def test_masses_from_dx_and_rho0_when_the_particles_have_none(tmp_path):
    """Fan/BIPI output: info dx and h, no masses: mass = rho0 dx^dim, density rho0, support info['h']."""
    atoms = alaric_like(2, True, origin=False)
    for name in ("masses", "momenta", "rho", "h"):
        del atoms.arrays[name]
    atoms.info.update(dx=0.25, h=0.65)
    data = swiftsimio.load(str(write_swift(atoms, tmp_path / "fan.hdf5", rho0=1000.0, cs2=1.0, kernel="wendland-C2")))
    np.testing.assert_allclose(data.gas.masses.v, 1000.0 * 0.25**2, rtol=TOL)
    np.testing.assert_allclose(data.gas.densities.v, 1000.0, rtol=TOL)
    np.testing.assert_allclose(data.gas.smoothing_lengths.v, 0.65 / 1.897367, rtol=TOL)


@pytest.mark.parametrize("kernel, dim, exact", [("cubic-spline", 1, np.sqrt(3.0)), ("cubic-spline", 3, np.sqrt(10 / 3)),
                                                ("wendland-C2", 3, np.sqrt(15 / 4)),
                                                ("quartic-spline", 1, np.sqrt(15 / 4))])
def test_swift_smoothing_length_is_support_over_gamma(kernel, dim, exact):
    """gamma_K = H / h, h = 2 sigma (Dehnen & Aly 2012): closed forms of the table's entries, to SWIFT's 7 digits."""
    assert SWIFT_KERNEL_GAMMA[kernel][dim] == pytest.approx(exact, rel=5e-7)
    assert swift_smoothing_length(0.2, kernel, dim) == pytest.approx(0.2 / exact, rel=5e-7)


def test_swift_has_no_1d_wendland_c4():
    with pytest.raises(ValueError, match="SWIFT has no 1D wendland-C4 kernel"):
        swift_smoothing_length(0.2, "wendland-C4", 1)


@settings(max_examples=40, deadline=None, database=None)
@given(st.integers(1, 3), st.lists(st.floats(-50.0, 50.0, allow_nan=False), min_size=3, max_size=30),
       st.floats(-3.0, 3.0, allow_nan=False), st.sampled_from([0.5, 1.0, 3.0]))
def test_box_frame_wraps_into_the_box_and_keeps_the_periodic_set(dim, values, origin, side):
    """Positions in [0, L); file position + shift = the position modulo L (degenerate: all equal, far images)."""
    n = len(values) // dim
    r_pc = np.zeros((n, 3))
    r_pc[:, :dim] = np.reshape(values[: n * dim], (n, dim))
    cell = np.diag([side if k < dim else 0.0 for k in range(3)])
    atoms = Atoms(numbers=np.zeros(n, int), positions=r_pc, cell=cell, pbc=[k < dim for k in range(3)])
    atoms.info["origin"] = [origin] * dim
    atoms.set_masses(np.ones(n))
    frame = box_frame(collect(atoms, dim))
    assert np.all(frame.r_pc[:, :dim] >= 0) and np.all(frame.r_pc[:, :dim] < side)
    assert np.all(frame.r_pc[:, dim:] == 0)
    turns = (frame.r_pc[:, :dim] + frame.shift_c[:dim] - r_pc[:, :dim]) / side
    np.testing.assert_allclose(turns, np.round(turns), atol=1e-9)


# -- bad input: one line, before anything is written ---------------------------------------------------------------
def _bad(name):
    atoms = alaric_like(2, True)
    if name == "nan positions":
        atoms.positions[3, 0] = np.nan
    elif name == "nan masses":
        masses = atoms.get_masses()
        masses[2] = np.nan
        atoms.arrays["masses"] = masses
    elif name == "no masses":
        del atoms.arrays["masses"], atoms.arrays["momenta"]
    elif name == "3D atoms":
        atoms.positions[:, 2] = np.linspace(0.0, 1.0, len(atoms))
    elif name == "walls":
        atoms.new_array("type", np.where(np.arange(len(atoms)) < 3, 2, 1))
    elif name == "mixed periodicity":
        atoms.pbc = [True, False, False]
    elif name == "3D motion":
        momenta = atoms.get_momenta()
        momenta[0, 2] = 1.0
        atoms.set_momenta(momenta)
    return atoms


@pytest.mark.parametrize("writer", [write_swift, write_gadget, write_vtu])
@pytest.mark.parametrize("name, message", [
    ("nan positions", "atoms.positions contains NaN"),
    ("nan masses", r"atoms.arrays\['masses'\] contains NaN"),
    ("no masses", "needs masses"),
    ("3D atoms", "2D"),
    ("walls", "fluid particles .type 1. only"),
    ("mixed periodicity", "periodic along every axis or none"),
    ("3D motion", "2D particles move along z"),
])
def test_bad_input_is_one_line_and_leaves_no_file(tmp_path, writer, name, message):
    atoms = _bad(name)
    path = tmp_path / "out.file"
    dim = 2 if name == "3D atoms" else None
    writes_anyway = writer is write_vtu and name in ("no masses", "walls", "mixed periodicity")
    if writes_anyway:  # VTU needs no masses, takes every type and any periodicity
        write_vtu(atoms, path, dim=dim)
        assert path.exists()
        return
    with pytest.raises(ValueError, match=message) as error:
        writer(atoms, path, dim=dim, cs2=1.0)
    assert "\n" not in str(error.value)
    assert list(tmp_path.iterdir()) == []


def test_swift_needs_internal_energy_and_gadget_refuses_a_box_it_cannot_run(tmp_path):
    atoms = alaric_like(2, True)
    with pytest.raises(ValueError, match="SWIFT needs internal energies"):
        write_swift(atoms, tmp_path / "s.hdf5")
    atoms.set_cell(np.diag([2.0, 1.5, 0.0]), scale_atoms=True)
    with pytest.raises(ValueError, match="BoxSize / 2.k"):
        write_gadget(atoms, tmp_path / "g.hdf5")
    with pytest.raises(ValueError, match="units must be one of"):
        write_swift(atoms, tmp_path / "s.hdf5", cs2=1.0, units="furlongs")
    assert list(tmp_path.iterdir()) == []


def test_gadget_internal_energy_zeros_when_unknown(tmp_path):
    """GADGET-4 reads zeros and sets the temperature from InitGasTemp (its documentation)."""
    with h5py.File(write_gadget(alaric_like(3, True), tmp_path / "g.hdf5")) as handle:
        np.testing.assert_array_equal(handle["PartType0/InternalEnergy"][:], 0.0)


# -- sphrelax export -------------------------------------------------------------------------------------------------
def test_cli_export_swift_and_vtu_round_trip(tmp_path, capsys):
    """The issue's check: sphrelax export --format swift IN.extxyz OUT.hdf5 and --format vtu."""
    from ase_sphrelax.cli import main

    write(tmp_path / "IN.extxyz", alaric_like(1, True), format="extxyz")
    atoms = read(tmp_path / "IN.extxyz")  # what the command reads (extxyz keeps 8 decimals)
    assert main(["export", "--format", "swift", str(tmp_path / "IN.extxyz"), str(tmp_path / "OUT.hdf5"),
                 "--cs2", "1", "--units", "si"]) == 0
    assert capsys.readouterr().out == f"wrote {tmp_path / 'OUT.hdf5'}\n"
    data = swiftsimio.load(str(tmp_path / "OUT.hdf5"))
    np.testing.assert_allclose(data.gas.coordinates.v[:, 0], atoms.positions[:, 0] + 1.0, rtol=0, atol=TOL)
    np.testing.assert_allclose(data.gas.masses.v, atoms.get_masses(), rtol=TOL)
    assert str(data.gas.masses.units) == "kg"
    assert main(["export", "--format", "vtu", str(tmp_path / "IN.extxyz"), str(tmp_path / "OUT.vtu")]) == 0
    mesh = meshio.read(tmp_path / "OUT.vtu")
    np.testing.assert_allclose(mesh.points, atoms.positions, rtol=0, atol=TOL)
    np.testing.assert_allclose(mesh.point_data["mass"], atoms.get_masses(), rtol=TOL)
    assert main(["export", str(tmp_path / "IN.extxyz"), str(tmp_path / "suffix.vtu")]) == 0
    assert main(["export", "--format", "gadget", str(tmp_path / "IN.extxyz"), str(tmp_path / "g.hdf5")]) == 0


@pytest.mark.parametrize("argv, message", [
    (["--format", "swift"], "SWIFT needs internal energies"),
    (["--format", "swift", "--cs2", "1", "--units", "metal"], "not a SWIFT unit system"),
    (["--format", "swift", "--cs2", "1", "--kernel", "wendland-C4"], "SWIFT has no 1D wendland-C4"),
    (["--format", "gadget", "--margin", "-1"], "margin must be a positive number"),
    (["--units", "galactic"], "not a LAMMPS units style"),
])
def test_cli_export_errors_are_one_line_and_write_nothing(tmp_path, capsys, argv, message):
    from ase_sphrelax.cli import main

    write(tmp_path / "IN.extxyz", alaric_like(1, True), format="extxyz")
    out = tmp_path / "out" / "OUT.data"
    out.parent.mkdir()
    assert main(["export", str(tmp_path / "IN.extxyz"), str(out), *argv]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert list(out.parent.iterdir()) == []


def test_cli_hdf5_suffix_needs_a_format(tmp_path, capsys):
    from ase_sphrelax.cli import main

    write(tmp_path / "IN.extxyz", alaric_like(1, True), format="extxyz")
    assert main(["export", str(tmp_path / "IN.extxyz"), str(tmp_path / "OUT.hdf5")]) == 2
    assert "--format" in capsys.readouterr().err


# -- LAMMPS keeps the particles' own masses and densities ----------------------------------------------------------
def _data_rows(path, section, n):
    lines = path.read_text().splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith(section)) + 2
    return np.array([line.split() for line in lines[start:start + n]], dtype=float)


def test_lammps_export_of_a_bounded_alaric_set_keeps_masses_and_densities(tmp_path):
    """Equal masses (ALARIC), per-particle rho, bounded 2D, no info['dx']: sph keeps both, no dx needed."""
    from ase_sphrelax.cli import main

    atoms = alaric_like(2, False)
    atoms.set_masses(np.full(len(atoms), 0.3))
    write(tmp_path / "IN.extxyz", atoms, format="extxyz")
    atoms = read(tmp_path / "IN.extxyz")  # what the command reads (extxyz keeps 8 decimals)
    assert main(["export", str(tmp_path / "IN.extxyz"), str(tmp_path / "out.data")]) == 0
    text = (tmp_path / "out.data").read_text().splitlines()
    assert float(text[text.index("Masses") + 2].split()[1]) == pytest.approx(0.3, rel=TOL)
    rows = _data_rows(tmp_path / "out.data", "Atoms # sph", len(atoms))
    np.testing.assert_allclose(rows[:, 2], atoms.arrays["rho"], rtol=TOL)
    np.testing.assert_allclose(rows[:, 5:7], atoms.positions[:, :2], rtol=0, atol=TOL)
    velocities = _data_rows(tmp_path / "out.data", "Velocities", len(atoms))
    np.testing.assert_allclose(velocities[:, 1:], atoms.get_velocities(), rtol=TOL, atol=TOL)


def test_lammps_sphere_export_keeps_each_particles_mass(tmp_path):
    """atom_style sphere stores mass as density * 4/3 pi r^3 per particle: the ALARIC-like masses come back."""
    atoms = alaric_like(3, True, origin=False)
    from lammps_io.cli import cli_export

    cli_export(atoms, tmp_path / "s.data", atom_style="sphere")
    rows = _data_rows(tmp_path / "s.data", "Atoms # sphere", len(atoms))
    mass_p = rows[:, 3] * 4.0 / 3.0 * np.pi * (rows[:, 2] / 2) ** 3
    np.testing.assert_allclose(mass_p, atoms.get_masses(), rtol=1e-12)
    np.testing.assert_allclose(rows[:, 2], (atoms.get_masses() / atoms.arrays["rho"]) ** (1 / 3), rtol=1e-12)


def test_an_explicit_dx_sets_every_mass_and_velocities_keep_the_particles_own_masses(tmp_path):
    """As for LAMMPS: --dx gives mass rho0 dx^dim and density rho0 to every particle; v = p / own mass."""
    atoms = alaric_like(3, True)
    data = swiftsimio.load(str(write_swift(atoms, tmp_path / "s.hdf5", dx=0.1, rho0=2.0, cs2=1.0)))
    np.testing.assert_allclose(data.gas.masses.v, 2.0 * 0.1**3, rtol=TOL)
    np.testing.assert_allclose(data.gas.densities.v, 2.0, rtol=TOL)
    np.testing.assert_allclose(data.gas.velocities.v, atoms.get_momenta() / atoms.get_masses()[:, None], rtol=TOL)
