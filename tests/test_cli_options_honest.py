"""Options that do what they say (issue 31 items 3, 5 and 9).

* ``--walls`` leaves a free surface open: ``--open-top`` or ``--surface Y`` (before: a lid always, 435 of 1101
  wall particles in a tank); ``--wall-mode``, ``--open-top`` and ``--surface`` without ``--walls`` are errors
  (before: silently ignored);
* ``--periodic`` on a shape whose extent is not a whole number of dx is an error unless ``--cell`` gives the period
  (before: a warning);
* ``sphrelax density --max-steps`` caps the steps and changes nothing else (before: also the pre-split stage
  length, ``max_steps // (K + 1)``);
* ``--profile mod:f`` says that the module must be importable (PYTHONPATH), in ``--help`` and in its error;
* ``--format vtk`` is read back by meshio (before: legacy POLYDATA, which meshio refuses).
"""
import json

import numpy as np
import pytest
from ase.io import read

from ase_sphrelax.cli import main
from ase_sphrelax.drivers.bipi_packer import FLUID, WALL

CAPS = ["--max-steps-2a", "5", "--max-steps-2c", "5", "--no-progress"]


def _edges(path, loop):
    path.write_text("".join(f"{a[0]} {a[1]} {b[0]} {b[1]}\n" for a, b in zip(loop, loop[1:] + loop[:1])))
    return path


@pytest.fixture
def tank(tmp_path):
    return _edges(tmp_path / "tank.edges", [(0.0, 0.0), (1.0, 0.0), (1.0, 0.5), (0.0, 0.5)])


@pytest.mark.parametrize("extra, message", [
    (["--wall-mode", "packed"], "--wall-mode needs --walls"),
    (["--wall-mode", "grid"], "--wall-mode needs --walls"),
    (["--open-top"], "--open-top needs --walls"),
    (["--surface", "0.5"], "--surface needs --walls"),
    (["--walls", "--surface", "0.3"], "--surface 0.3: the fluid reaches y = 0.5"),
])
def test_wall_options_without_walls_or_below_the_water_are_errors(tank, tmp_path, capsys, extra, message):
    assert main(["pack", "--boundary", str(tank), "--dx", "0.1", "--out", str(tmp_path / "o"), *CAPS, *extra]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("sphrelax pack: error: " + message), err


@pytest.mark.parametrize("option", [["--open-top"], ["--surface", "0.5"], ["--surface", "0.52"]])
def test_open_top_builds_no_lid(tank, tmp_path, option):
    runs = {}
    for name, extra in (("closed", []), ("open", option)):
        out = tmp_path / name
        assert main(["pack", "--boundary", str(tank), "--dx", "0.05", "--walls", "2", "--out", str(out), *CAPS,
                     *extra]) == 0
        runs[name] = read(out / "packed.extxyz")
    closed, opened = runs["closed"], runs["open"]
    y_closed = closed.positions[closed.arrays["type"] == WALL, 1]
    y_open = opened.positions[opened.arrays["type"] == WALL, 1]
    level = 0.5 if option[0] == "--open-top" else float(option[1])
    assert y_closed.max() > 0.5 and (y_closed >= level).sum() > 0  # the lid, as before
    assert y_open.max() < level and y_open.max() > 0.5 - 0.05  # side walls up to the surface, no lid
    assert (y_open < 0.5).sum() == (y_closed < 0.5).sum()  # the same walls below the surface
    assert np.array_equal(opened.arrays["type"] == FLUID, np.arange(len(opened)) < (opened.arrays["type"] == FLUID).sum())
    summary = json.loads((tmp_path / "open" / "summary.json").read_text())["summary"]
    assert summary["surface"] == pytest.approx(level) and summary["n_wall"] == len(y_open)


def test_packed_walls_open_top(tank, tmp_path):
    out = tmp_path / "packed"
    assert main(["pack", "--boundary", str(tank), "--dx", "0.05", "--walls", "2", "--wall-mode", "packed",
                 "--open-top", "--out", str(out), *CAPS]) == 0
    both = read(out / "packed.extxyz")
    y = both.positions[both.arrays["type"] == WALL, 1]
    assert len(y) > 0 and y.max() < 0.5


def test_periodic_extent_not_a_whole_number_of_dx_is_an_error(tmp_path, capsys):
    channel = _edges(tmp_path / "channel.edges", [(0.0, 0.0), (1.03, 0.0), (1.03, 0.4), (0.0, 0.4)])
    code = main(["pack", "--boundary", str(channel), "--dx", "0.1", "--periodic", "x", "--out", str(tmp_path / "a"),
                 *CAPS])
    err = capsys.readouterr().err
    assert code == 2 and "sphrelax pack: error: --periodic x: the boundary's extent along x is 1.03 = 10.3 dx" in err
    assert "--cell" in err
    # a period given with --cell is the user's choice (a warning in the one-line form at most)
    assert main(["pack", "--boundary", str(channel), "--dx", "0.1", "--periodic", "x", "--cell", "1.03", "0",
                 "--out", str(tmp_path / "b"), *CAPS]) == 0
    # a whole number of dx runs
    assert main(["pack", "--boundary", str(channel), "--dx", "0.103", "--periodic", "x", "--out", str(tmp_path / "c"),
                 *CAPS]) == 0


class _Stop(Exception):
    pass


@pytest.mark.parametrize("max_steps", [None, "40", "100000"])
def test_density_max_steps_caps_and_nothing_else(monkeypatch, tmp_path, max_steps):
    import ase_sphrelax.drivers.alaric_dynamics as dynamics
    from ase_sphrelax.cli.density import MAX_STEPS

    seen = {}

    def fake(atoms, density, dim, **kwargs):
        seen.update(kwargs)
        raise _Stop

    monkeypatch.setattr(dynamics, "relax_density", fake)
    args = ["density", "--dim", "1", "--n", "303", "--split", "1", "--out", str(tmp_path), "--no-progress"]
    with pytest.raises(_Stop):
        main(args + ([] if max_steps is None else ["--max-steps", max_steps]))
    assert seen["max_steps"] == (MAX_STEPS if max_steps is None else int(max_steps))
    assert seen["stage_steps"] == MAX_STEPS // 2  # the pre-split stage does not follow --max-steps
    assert seen["split_at_cap"] is True  # a cap before the split still gives --n particles


def test_profile_says_it_needs_pythonpath(tmp_path, capsys):
    with pytest.raises(SystemExit):
        main(["density", "--help"])
    assert "PYTHONPATH" in capsys.readouterr().out
    assert main(["density", "--profile", "no_such_module_31:f", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "cannot import 'no_such_module_31'" in err[0] and "PYTHONPATH" in err[0], err


def test_vtk_is_read_back_by_meshio(tmp_path):
    meshio = pytest.importorskip("meshio")
    from ase_sphrelax.build import periodic_box
    from lammps_io.cli import cli_export

    atoms = periodic_box((4, 3), dx=0.5, dim=2, jitter=0.1, seed=0)
    atoms.arrays["type"] = np.arange(len(atoms)) % 2 + 1
    atoms.arrays["v"] = np.arange(3 * len(atoms), dtype=float).reshape(-1, 3)
    cli_export(atoms, tmp_path / "a.vtk")
    mesh = meshio.read(tmp_path / "a.vtk")
    np.testing.assert_allclose(mesh.points, atoms.positions)
    assert mesh.cells[0].type == "vertex" and len(mesh.cells[0].data) == len(atoms)
    np.testing.assert_array_equal(mesh.point_data["type"].ravel(), atoms.arrays["type"])
    np.testing.assert_allclose(mesh.point_data["v"], atoms.arrays["v"])
