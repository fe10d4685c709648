"""lammps_io.cli: export (lammps/extxyz/vtk) and relax --engine lammps helpers."""
import argparse
import json

import numpy as np
import pytest
from ase.io import read

import lammps_io
from ase_sphrelax.build import fill, periodic_box
from ase_sphrelax.domains import Circle
from lammps_io import _library
from lammps_io.cli import add_engine_arguments, add_export_arguments, cli_export, cli_relax

pytestmark = pytest.mark.lammps
needs_lammps = pytest.mark.skipif(not lammps_io.lammps_available(), reason="lammps wheel not importable")


def test_export_extxyz_and_vtk(tmp_path):
    atoms = periodic_box((4, 3), dx=0.5, dim=2, jitter=0.1, seed=0)
    atoms.arrays["phi"] = np.linspace(-1, 0, len(atoms))
    cli_export(atoms, tmp_path / "a.xyz")
    back = read(tmp_path / "a.xyz")
    np.testing.assert_allclose(back.positions, atoms.positions)
    cli_export(atoms, tmp_path / "a.vtk")
    text = (tmp_path / "a.vtk").read_text().splitlines()
    assert "POINTS 12 double" in text and "CELLS 12 24" in text and "SCALARS phi double 1" in text
    start = text.index("POINTS 12 double") + 1
    np.testing.assert_allclose(np.array([line.split() for line in text[start:start + 12]], float), atoms.positions)
    with pytest.raises(ValueError, match="--format"):
        cli_export(atoms, tmp_path / "a.unknown")


@needs_lammps
def test_export_lammps_sph_mass_and_density(tmp_path):
    """atom_style sph export: rho = rho0, mass = rho0 dx^2, open sets get a dx margin."""
    domain = Circle((0.0, 0.0), 3.0)
    atoms = fill(domain, 0.5, jitter=0.1, seed=0)
    cli_export(atoms, tmp_path / "c.data", rho0=1000.0, units="si")
    lmp = _library.new_lammps()
    lmp.commands_list(["units si", "dimension 2", "boundary f f p", "atom_style sph", "atom_modify map array",
                       f"read_data {tmp_path / 'c.data'}"])
    n = lmp.get_natoms()
    assert n == len(atoms)
    np.testing.assert_allclose(np.array(lmp.gather_atoms("rho", 1, 1)[:n]), 1000.0)
    assert lmp.extract_atom("mass")[1] == pytest.approx(1000.0 * 0.25)
    boxlo, boxhi = lmp.extract_box()[:2]
    assert boxlo[0] == pytest.approx(atoms.positions[:, 0].min() - 0.5)
    assert boxhi[1] == pytest.approx(atoms.positions[:, 1].max() + 0.5)
    lmp.close()


@needs_lammps
def test_relax_engine_lammps_writes_extxyz(tmp_path):
    start = periodic_box((6, 6), dx=1.0, dim=2, lattice="hexagonal", jitter=0.1, seed=4)
    relaxed = cli_relax(start, 2.6, 1.0, steps=500, output=tmp_path / "r.xyz")
    back = read(tmp_path / "r.xyz")
    np.testing.assert_allclose(back.positions, relaxed.positions)
    assert back.info["lammps_energy"] == pytest.approx(relaxed.info["lammps"]["energy"])


def test_argparse_helpers():
    parser = argparse.ArgumentParser()
    sub = parser.add_subparsers(dest="cmd")
    add_export_arguments(sub.add_parser("export"))
    add_engine_arguments(sub.add_parser("relax"))
    args = parser.parse_args(["export", "in.xyz", "out.data", "--format", "lammps", "--atom-style", "sphere"])
    assert (args.format, args.atom_style, args.units, args.rho0) == ("lammps", "sphere", "lj", 1.0)
    args = parser.parse_args(["relax", "--engine", "lammps", "--nprocs", "2"])
    assert (args.engine, args.nprocs, args.nthreads, args.lammps_style) == ("lammps", 2, 1, "table")
    with pytest.raises(SystemExit):
        parser.parse_args(["export", "a", "b", "--units", "furlongs"])


def test_export_and_engine_come_from_lammps_io_entry_points(tmp_path, capsys):
    """sphrelax finds lammps_io's command and engine through the entry points of pyproject.toml."""
    from importlib.metadata import entry_points

    from ase_sphrelax.cli import main, registry
    from lammps_io.cli import ExportCommand, LammpsEngine

    commands = {ep.name: ep.value for ep in entry_points(group=registry.COMMAND_GROUP)}
    engines = {ep.name: ep.value for ep in entry_points(group=registry.ENGINE_GROUP)}
    assert commands["export"] == "lammps_io.cli:ExportCommand" and engines["lammps"] == "lammps_io.cli:LammpsEngine"
    assert "export" not in registry.COMMANDS and "lammps" not in registry.ENGINES
    assert registry.commands()["export"] is ExportCommand and registry.engines()["lammps"] is LammpsEngine
    atoms = periodic_box((4, 3), dx=0.5, dim=2, jitter=0.1, seed=0)
    atoms.write(tmp_path / "in.extxyz")
    assert main(["export", str(tmp_path / "in.extxyz"), str(tmp_path / "out.vtk")]) == 0
    assert capsys.readouterr().out == f"wrote {tmp_path / 'out.vtk'}\n"
    assert "POINTS 12 double" in (tmp_path / "out.vtk").read_text()
    assert main(["export", str(tmp_path / "missing.extxyz"), str(tmp_path / "out.vtk")]) == 2
    assert "does not exist" in capsys.readouterr().err


@needs_lammps
def test_relax_engine_lammps_from_the_command_line(tmp_path, capsys):
    from ase_sphrelax.cli import main

    assert main(["relax", "--engine", "lammps", "--dx", "0.05", "--steps", "50", "--out", str(tmp_path)]) == 0
    assert "engine = lammps, optimizer = lammps fire" in capsys.readouterr().out
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["engine"] == "lammps" and 0 < summary["steps"] <= 50
    assert summary["energy_after"] < summary["energy_before"]


def test_relax_engine_lammps_without_lammps_is_a_usage_error(tmp_path, capsys, monkeypatch):
    from ase_sphrelax.cli import main

    def missing():
        raise ImportError(f"the LAMMPS Python module is not usable; install `{lammps_io.INSTALL_HINT}`")

    monkeypatch.setattr(_library, "import_lammps", missing)
    assert main(["relax", "--engine", "lammps", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("sphrelax relax: error: --engine lammps: the LAMMPS Python module is not usable")
    assert lammps_io.INSTALL_HINT in err and err.count("\n") == 1


# -- issue 10 item 2: the LAMMPS engine reports what LAMMPS did ---------------------------------------------
LOG = """minimize 0.0 1e-10 50000 500010
   Step          PotEng         Fnorm          Fmax
         0   0.010230510     0.0123         0.0041
       100   0.009300000     0.0012         0.0004
      2665   0.009163317     1e-12          1e-13
Loop time of 1.2 on 1 procs for 2665 steps with 316 atoms

Minimization stats:
  Stopping criterion = force tolerance
  Energy initial, next-to-last, final =
  Iterations, force evaluations = 2665 2674
"""


def test_minimize_report_and_thermo_steps_are_read_from_the_log(tmp_path):
    from lammps_io.relaxation import _thermo_steps, minimize_report

    log = tmp_path / "log.lammps"
    log.write_text(LOG)
    assert minimize_report(log) == dict(stop_reason="force tolerance", iterations=2665, force_evaluations=2674)
    assert minimize_report(tmp_path / "missing") == {}
    step, position = _thermo_steps(log, 0)
    assert step == 2665 and position == len(LOG.encode())
    assert _thermo_steps(log, position) == (None, position)


def _lammps_relax(tmp_path, *args):
    from ase_sphrelax.cli import main

    code = main(["relax", "--engine", "lammps", "--dx", "0.02", "--out", str(tmp_path)] + list(args))
    return code, (json.loads((tmp_path / "summary.json").read_text()) if code == 0 else None)


@needs_lammps
def test_lammps_engine_reports_real_iterations_and_the_stop_reason(tmp_path):
    """--steps 50000 on the 316-particle circle: LAMMPS converges after some 2700 iterations, and says so."""
    code, summary = _lammps_relax(tmp_path / "a", "--steps", "50000")
    assert code == 0 and 100 < summary["steps"] < 50000
    assert "force tolerance" in summary["stop_reason"] and "min_style fire" in summary["stop_reason"]
    code, summary = _lammps_relax(tmp_path / "b", "--steps", "30")
    assert code == 0 and summary["steps"] == 30 and "max iterations" in summary["stop_reason"]


@needs_lammps
def test_lammps_engine_passes_fmax_to_the_minimiser(tmp_path):
    code, full = _lammps_relax(tmp_path / "full", "--steps", "2000")
    code, early = _lammps_relax(tmp_path / "early", "--steps", "2000", "--fmax-rel", "0.5")
    assert code == 0 and early["steps"] < full["steps"] / 10
    assert "force tolerance (max |F| <" in early["stop_reason"]
    assert full["energy_after"] < early["energy_after"] < early["energy_before"]


@needs_lammps
def test_lammps_engine_maps_optimizers_to_min_styles_or_refuses(tmp_path, capsys):
    code, summary = _lammps_relax(tmp_path / "cg", "--steps", "200", "--min-style", "cg")
    assert code == 0 and summary["optimizer"] == "lammps cg" and "min_style cg" in summary["stop_reason"]
    for args, message in ((["--optimizer", "bfgs"], "--optimizer bfgs has no LAMMPS counterpart"),
                          (["--optimizer", "fire", "--min-style", "sd"], "disagree"),
                          (["--c", "0.1"], "--c applies to --engine ase only")):
        assert _lammps_relax(tmp_path / "x", *args)[0] == 2
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1
