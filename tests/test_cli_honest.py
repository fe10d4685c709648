"""Issue 10 items 4-7 at the command line: clear one-line errors, warnings that say what will happen,
--strict, honest stop reasons and wall times, the same name meaning the same thing."""
import json
import math

import numpy as np
import pytest

from ase_sphrelax.cli import build_parser, main, registry


def _relax(tmp_path, *args):
    return main(["relax", "--dx", str(1 / 40), "--steps", "20", "--out", str(tmp_path)] + list(args))


def _summary(tmp_path):
    return json.loads((tmp_path / "summary.json").read_text(), parse_constant=lambda c: pytest.fail(f"JSON has {c}"))


# -- item 7: names --------------------------------------------------------------------------------------
def test_every_option_of_every_command_has_help():
    parser = build_parser()
    commands = next(a for a in parser._actions if a.dest == "command").choices
    missing = [f"{name} {action.option_strings or action.dest}" for name, sub in commands.items()
               for action in sub._actions if action.dest not in ("help",) and not action.help]
    assert missing == []


def test_h_is_an_alias_of_h_over_dx(tmp_path):
    """--h keeps working (h in units of dx, as before); --h-over-dx says what it is."""
    assert _relax(tmp_path / "a", "--h", "2.2") == 0 and _relax(tmp_path / "b", "--h-over-dx", "2.2") == 0
    a, b = _summary(tmp_path / "a"), _summary(tmp_path / "b")
    assert a["h_over_dx"] == b["h_over_dx"] == 2.2 and a["energy_after"] == b["energy_after"]


def test_fmax_is_absolute_as_in_python_and_fmax_rel_is_relative(tmp_path):
    from ase_sphrelax import FanCalculator
    from ase_sphrelax.cli.scene import make_scene

    scene = make_scene("circle", dx=1 / 40)
    f0 = np.linalg.norm(FanCalculator(h=2.6 / 40, dx=1 / 40, domain=scene.domain).get_forces(scene.atoms), axis=1).max()
    assert _relax(tmp_path / "abs", "--fmax", str(2 * f0)) == 0  # above every force: converged at step 0
    assert _summary(tmp_path / "abs")["steps"] == 0
    assert _relax(tmp_path / "rel", "--fmax-rel", "0.5", "--steps", "2000") == 0
    summary = _summary(tmp_path / "rel")
    assert 0 < summary["steps"] < 2000 and "--fmax-rel 0.5" in summary["stop_reason"]
    with pytest.raises(SystemExit):  # one or the other
        main(["relax", "--fmax", "1", "--fmax-rel", "0.1"])


def test_table_csv_has_one_name():
    from pathlib import Path

    from ase_sphrelax.analysis.patterns import table_path

    assert table_path(2).name == "table2_2d.csv" and table_path(3, "x").as_posix() == "x/table2_3d.csv"
    example = (Path(__file__).parents[1] / "reproductions" / "lattice-table2" / "run.py").read_text()
    assert "table_path(2" in example and "table2d" not in example


# -- item 5: nonsense settings ------------------------------------------------------------------------------
@pytest.mark.parametrize("args, message", [
    (["--h", "0.5"], "--h-over-dx (--h) must be > 1"),
    (["--c", "5"], "--c must be < 1"),
    (["--nprocs", "2"], "--nprocs applies to --engine lammps only; this run uses --engine ase"),
    (["--lammps-style", "lepton"], "--lammps-style applies to --engine lammps only"),
    (["--jitter", "0.7"], "--jitter must be in [0, 0.5)"),
    (["--domain", "no_such_file.edges"], "--domain must be one of"),
])
def test_nonsense_settings_are_one_line_errors(tmp_path, capsys, args, message):
    assert _relax(tmp_path, *args) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1 and not (tmp_path / "summary.json").exists()


@pytest.mark.parametrize("args", [["--fmax", "-1"], ["--fmax-rel", "-0.1"], ["--fmax", "nan"]])
def test_negative_fmax_is_refused_while_parsing(args):
    with pytest.raises(SystemExit):
        main(["relax"] + args)


@pytest.mark.parametrize("args, message", [
    (["--h", "1.2"], "fewer than about 6 neighbours"),
    (["--c", "0.3"], "steps of 0.3 h"),
    (["--domain", "circle", "--dx", "0.05"], "N dx^2 = 1.0345 x the domain volume"),
])
def test_doubtful_settings_warn_and_strict_refuses_them(tmp_path, capsys, args, message):
    assert _relax(tmp_path / "run", *args) == 0
    err = capsys.readouterr().err
    assert f"sphrelax relax: warning: " in err and message in err
    assert _relax(tmp_path / "strict", *args, "--strict") == 2
    err = capsys.readouterr().err
    assert message in err and "--strict makes this an error" in err


class EscapeEngine:
    """test engine: moves one particle 0.5 outside the domain"""

    methods = None

    @staticmethod
    def describe(args):
        return "escape"

    @staticmethod
    def relax(atoms, scene, h, args):
        atoms.positions[0, 0] = scene.domain.bounds[1][0] + 0.5
        return atoms, 1, "moved a particle out"


def test_particles_outside_at_the_end_are_said_on_the_last_line(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(registry.ENGINES, "escape", "test_cli_honest:EscapeEngine")
    assert _relax(tmp_path, "--engine", "escape") == 0
    last = capsys.readouterr().out.rstrip("\n").splitlines()[-1]
    assert last.startswith("WARNING: ") and "particle(s) ended outside the domain" in last and "--strict" in last
    assert _relax(tmp_path, "--engine", "escape", "--strict", "--particle-volume", "V/N", "--overwrite") == 1
    assert "exit status 1 (--strict)" in capsys.readouterr().out.rstrip("\n").splitlines()[-1]


# -- items 3 and 6: summary, metrics, wall times, progress ------------------------------------------------
def test_summary_reports_real_steps_both_wall_times_and_the_lattice_optimum(tmp_path, capsys):
    assert _relax(tmp_path, "--steps", "15") == 0
    out = capsys.readouterr().out
    summary = _summary(tmp_path)
    assert summary["steps"] == 15 and summary["stop_reason"] == "reached --steps 15"
    assert "wall time: relaxation" in out and "whole command" in out
    assert summary["command_time_s"] > summary["wall_time_s"] > 0
    optimum = summary["lattice_optimum"]
    assert optimum["pattern"] == "hexagonal" and optimum["inverse_v_c"] == pytest.approx(1 / 0.991235, abs=1e-5)
    assert "lattice optimum 1/v_c" in out and "mean Σ V W (interior)" in out


def test_particle_volume_v_over_n(tmp_path):
    from ase_sphrelax.cli.scene import make_scene

    assert _relax(tmp_path, "--particle-volume", "V/N") == 0
    summary = _summary(tmp_path)
    scene = make_scene("circle", dx=1 / 40)
    assert summary["particle_volume"] == "V/N"
    assert summary["v0"] == pytest.approx(scene.domain.volume / len(scene.atoms), rel=1e-12)
    assert summary["v0"] != pytest.approx((1 / 40) ** 2, rel=1e-3)


def test_metrics_print_na_never_nan(capsys):
    from ase_sphrelax.cli.relax import _print_quality

    before = dict(kernel_sum_error_mean=None, n_outside=0, boundary_distance_mean=None)
    after = dict(kernel_sum_error_mean=0.01, n_outside=0, boundary_distance_mean=0.5)
    _print_quality(before, after)
    out = capsys.readouterr().out
    assert "n/a" in out and "nan" not in out.lower()


def test_progress_bar_counts_the_steps_not_the_observer_calls():
    """The bar ended at '1501step' for --steps 1500: ASE calls observers at step 0 too."""
    from ase_sphrelax import FanCalculator
    from ase_sphrelax.cli.relax import _progress
    from ase_sphrelax.cli.scene import make_scene
    from ase_sphrelax.drivers import make_optimizer

    scene = make_scene("circle", dx=1 / 32)
    atoms = scene.atoms
    atoms.calc = FanCalculator(h=2.6 / 32, dx=1 / 32, domain=scene.domain)
    opt = make_optimizer("fan", atoms)
    import io

    bar = _progress(opt, atoms, 12, "test", disable=False, file=io.StringIO())
    opt.run(fmax=0, steps=12)
    assert bar.n == opt.nsteps == 12
    bar.close()


# -- item 4: one-line errors naming the parameter or file -------------------------------------------------
def test_lattice_h_below_one_is_a_usage_error(capsys):
    assert main(["lattice", "--h", "0.3"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("sphrelax lattice: error: --h-over-dx (--h) must be > 1") and err.count("\n") == 1


def test_export_of_a_file_that_is_not_particles(tmp_path, capsys):
    (tmp_path / "summary.json").write_text('{"steps": 3}')
    assert main(["export", str(tmp_path / "summary.json"), str(tmp_path / "x.data")]) == 2
    err = capsys.readouterr().err
    assert "summary.json' is not a particle file ase.io.read understands" in err and err.count("\n") == 1


@pytest.mark.parametrize("text, message", [
    ("# a comment\n0 0 1 0\n\n1 0 1\n1 1 0 1\n", r"bad\.edges: line 4: expected 4 numbers 'x1 y1 x2 y2'"),
    ("0 0 1 0\n1 0 1 x\n", r"bad\.edges: line 2: expected 4 numbers"),
    ("", r"bad\.edges: an edge file needs at least 3 lines .* the file has no segment"),
    ("0 0 1 0\n1 0 1 1\n1 1 0 1\n0 1 0.2 0.3\n", r"not closed at \(0, 0\).*bad\.edges: segment\(s\) 0 \(line\(s\) 1\)"),
])
def test_edge_file_errors_name_the_file_and_line(tmp_path, capsys, text, message):
    import re
    import warnings

    from ase_sphrelax.domains import Polygon

    path = tmp_path / "bad.edges"
    path.write_text(text)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no numpy UserWarning for an empty file
        with pytest.raises(ValueError, match=message) as error:
            Polygon.from_edges(path)
    assert not str(error.value).startswith("path:")
    assert main(["relax", "--domain", str(path), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert re.search(message, err) and err.count("\n") == 1


def test_polygon_of_a_path_points_to_from_edges(tmp_path):
    from ase_sphrelax.domains import Polygon

    with pytest.raises(TypeError, match=r"Polygon\.from_edges\('x\.edges'\)"):
        Polygon("x.edges")


def test_empty_atoms_are_one_line_errors_everywhere():
    from ase import Atoms

    from ase_sphrelax import FanCalculator
    from ase_sphrelax.analysis import quality_summary
    from lammps_io.cli import cli_export

    empty = Atoms(cell=[1, 1, 1], pbc=True)
    for call in (lambda: FanCalculator(h=0.1).get_potential_energy(empty),
                 lambda: quality_summary(empty, h=0.1),
                 lambda: cli_export(empty, "x.data")):
        with pytest.raises(ValueError, match="need at least one particle"):
            call()
