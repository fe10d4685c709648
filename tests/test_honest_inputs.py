"""Issue 22, inputs and verdicts: pack's --h rules and its verdict, fill sizes, BIPI spacing, meshes that are not
volumes, file-type messages, the shared CLI habits (--out, --overwrite, --progress, summary.json), the MPI
worker's JSON arguments and WVT's dimension rule."""
import json
import subprocess
import sys
import warnings

import numpy as np
import pytest
import trimesh
from ase import Atoms

from ase_sphrelax.cli import main

GEOMETRIES = "/work/shared/geometries"


@pytest.fixture
def square(tmp_path):
    path = tmp_path / "square.edges"
    path.write_text("0 0 1 0\n1 0 1 1\n1 1 0 1\n0 1 0 0\n")
    return path


@pytest.fixture
def overlapping_stl(tmp_path):
    a = trimesh.creation.box(extents=[1, 1, 1])
    b = trimesh.creation.box(extents=[1, 1, 1])
    b.apply_translation([0.5, 0.3, 0.2])
    path = tmp_path / "overlap.stl"
    trimesh.util.concatenate([a, b]).export(path)
    return path


def _one_line_error(capsys):
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "Traceback" not in err[0], err
    return err[0]


def _summary(out):
    return json.loads((out / "summary.json").read_text())


# -- problem 3: pack with a small --h ----------------------------------------------------------------------
@pytest.mark.parametrize("option", [["--h", "1"], ["--h-paper", "0.5"]])
def test_pack_refuses_a_support_of_one_dx_and_names_both_conventions(square, tmp_path, capsys, option):
    code = main(["pack", "--boundary", str(square), "--dx", "0.1", *option, "--out", str(tmp_path / "o"),
                 "--max-steps-2a", "2", "--max-steps-2c", "2"])
    assert code == 2
    line = _one_line_error(capsys)
    assert "--h 1" in line and "--h-paper 0.5" in line and "at least dx" in line


def test_pack_warns_below_one_and_a_half_dx_and_strict_refuses(square, tmp_path, capsys):
    base = ["pack", "--boundary", str(square), "--dx", "0.1", "--h", "1.4", "--max-steps-2a", "2",
            "--max-steps-2c", "2"]
    assert main(base + ["--out", str(tmp_path / "a")]) == 0
    assert "warning: --h 1.4 (= --h-paper 0.7" in capsys.readouterr().err
    assert main(base + ["--out", str(tmp_path / "b"), "--strict"]) == 2
    assert "--strict" in _one_line_error(capsys)


def test_pack_that_ends_worse_than_it_started_is_not_converged(tmp_path, capsys):
    """The issue's run: TrapezoidalTank, dx 0.04, --h 2 raised |grad C|_avg from 0.395 to 5.12 with exit 0."""
    out = tmp_path / "o"
    code = main(["pack", "--boundary", f"{GEOMETRIES}/TrapezoidalTank.edges", "--dx", "0.04", "--h", "2",
                 "--out", str(out)])
    assert code == 3
    s = _summary(out)
    assert s["converged"] is False and "worse than it started" in s["convergence_reason"]
    assert "not converged" in capsys.readouterr().err


# -- problem 10 (pack): all particles frozen ---------------------------------------------------------------
def test_pack_with_every_particle_frozen_is_degenerate(square, tmp_path, capsys):
    out = tmp_path / "o"
    assert main(["pack", "--boundary", str(square), "--dx", "0.5", "--out", str(out)]) == 3
    s = _summary(out)
    assert s["converged"] is False and s["convergence_reason"].startswith("degenerate")
    assert s["summary"]["iterations_2c"] == 0  # no no-op iterations
    text = capsys.readouterr()
    assert "nan orders" not in text.out and "degenerate" in text.err


def test_bipi_packer_warns_when_not_converged(square):
    from ase_sphrelax.calculators.bipi import BIPICalculator
    from ase_sphrelax.checks import NotConvergedWarning
    from ase_sphrelax.drivers.bipi_packer import BIPIPacker, initial_fill

    atoms = initial_fill(str(square), 0.1)
    packer = BIPIPacker(atoms, BIPICalculator(h=0.4, dx=0.1, boundary=str(square)), max_steps_2a=3, max_steps_2c=3)
    with pytest.warns(NotConvergedWarning, match="cap of 3 iterations"):
        packer.run()
    assert packer.verdict()[0] is False


# -- problem 9: sizes before a fill ------------------------------------------------------------------------
def test_fill_refuses_past_max_particles_with_the_estimate():
    from ase_sphrelax.build import fill
    from ase_sphrelax.domains import Box

    with pytest.raises(ValueError, match=r"about 1\.09e\+05 particles.*max_particles=1e\+05"):
        fill(Box((0, 0), (1, 1)), 1 / 330, max_particles=1e5)
    assert len(fill(Box((0, 0), (1, 1)), 1 / 330, max_particles=2e5)) == 330**2


def test_fill_refuses_the_issue_case_by_default_at_once():
    """--dx 1e-4 on the unit square: 1e8 particles died of MemoryError after 25 s."""
    import time

    from ase_sphrelax.build import fill
    from ase_sphrelax.domains import Box

    t = time.perf_counter()
    with pytest.raises(ValueError, match=r"about 1e\+08 particles, about \d+ GB"):
        fill(Box((0, 0), (1, 1)), 1e-4)
    assert time.perf_counter() - t < 2.0


@pytest.mark.parametrize("command", ["relax", "pack"])
def test_cli_prints_the_estimate_and_refuses_past_max_particles(command, square, tmp_path, capsys):
    where = ["--domain", str(square)] if command == "relax" else ["--boundary", str(square)]
    code = main([command, *where, "--dx", "0.01", "--max-particles", "5000", "--out", str(tmp_path / "o")])
    assert code == 2
    text = capsys.readouterr()
    assert "about 1e+04 particles" in text.out  # printed before the fill
    assert "--max-particles" in text.err and "about 1e+04 particles" in text.err
    assert len(text.err.strip().splitlines()) == 1


# -- problem 5: BIPI particles at another spacing ----------------------------------------------------------
def test_bipi_calculator_warns_when_particles_are_at_another_spacing():
    from ase_sphrelax.boundary import BoundarySegments
    from ase_sphrelax.calculators.bipi import BIPICalculator
    from ase_sphrelax.checks import SpacingWarning
    from ase_sphrelax.drivers.bipi_packer import initial_fill

    boundary = BoundarySegments.from_edges(f"{GEOMETRIES}/TrapezoidalTank.edges")
    atoms = initial_fill(boundary, 0.025)
    atoms.calc = BIPICalculator(h=0.2, dx=0.05, boundary=boundary)
    with pytest.warns(SpacingWarning, match=r"spaced about 0\.02"):
        atoms.get_potential_energy()
    same = initial_fill(boundary, 0.05)
    same.calc = BIPICalculator(h=0.2, dx=0.05, boundary=boundary)
    with warnings.catch_warnings():
        warnings.simplefilter("error", SpacingWarning)
        same.get_potential_energy()


# -- problem 8: meshes that are not volumes ----------------------------------------------------------------
def test_overlapping_mesh_is_refused_by_mesh_and_boundary(overlapping_stl):
    from ase_sphrelax.boundary.triangles import BoundaryTriangles
    from ase_sphrelax.domains import Mesh

    with pytest.raises(ValueError, match="self-intersecting"):
        Mesh(str(overlapping_stl))
    with pytest.raises(ValueError, match="self-intersecting"):
        BoundaryTriangles.from_file(overlapping_stl)


def test_a_cavity_and_an_island_in_it_are_one_volume():
    from ase_sphrelax.domains import Mesh

    box = trimesh.creation.box(extents=[2, 2, 2])
    cavity = trimesh.creation.icosphere(radius=0.5)
    cavity.invert()
    island = trimesh.creation.icosphere(radius=0.2)
    mesh = Mesh(trimesh.util.concatenate([box, cavity, island]))
    assert mesh.volume == pytest.approx(8 - cavity.convex_hull.volume + island.volume, rel=1e-9)
    with pytest.raises(ValueError, match="self-intersecting"):  # a second outward sphere inside the box
        Mesh(trimesh.util.concatenate([box, trimesh.creation.icosphere(radius=0.5)]))


@pytest.mark.parametrize("command", ["pack", "relax"])
def test_cli_refuses_an_overlapping_mesh_in_one_line(command, overlapping_stl, tmp_path, capsys):
    where = ["--boundary"] if command == "pack" else ["--domain"]
    assert main([command, *where, str(overlapping_stl), "--dx", "0.1", "--out", str(tmp_path / "o")]) == 2
    assert "self-intersecting" in _one_line_error(capsys)


def test_inconsistent_winding_and_open_meshes_are_one_line(tmp_path):
    from ase_sphrelax.domains.mesh import check_volume

    box = trimesh.creation.box()
    open_box = trimesh.Trimesh(box.vertices, box.faces[:-1], process=False)
    with pytest.raises(ValueError, match="watertight"):
        check_volume(open_box)
    flipped = trimesh.Trimesh(box.vertices, np.vstack([box.faces[:-1], box.faces[-1:, ::-1]]), process=False)
    with pytest.raises(ValueError, match="winding"):
        check_volume(flipped)


# -- unclear messages: garbage .stl, an edge file without an extension -------------------------------------
def test_garbage_stl_and_extensionless_edge_file_messages(tmp_path, capsys):
    garbage = tmp_path / "garbage.stl"
    garbage.write_bytes(np.random.default_rng(0).bytes(3000))
    assert main(["pack", "--boundary", str(garbage), "--dx", "0.1", "--out", str(tmp_path / "a")]) == 2
    line = _one_line_error(capsys)
    assert "no triangles" in line and "charset" not in line
    plain = tmp_path / "tank"
    plain.write_text(open(f"{GEOMETRIES}/TrapezoidalTank.edges").read())
    assert main(["pack", "--boundary", str(plain), "--dx", "0.1", "--out", str(tmp_path / "b")]) == 2
    line = _one_line_error(capsys)
    assert "no extension" in line and ".edges" in line


# -- problem 6 (WVT part): a dimension mismatch is an error ------------------------------------------------
def test_wvt_refuses_2d_atoms_with_dim_1():
    from ase_sphrelax.drivers.wvt import WVTRelaxation

    r = np.zeros((20, 3))
    r[:, :2] = np.random.default_rng(0).random((20, 2))
    atoms = Atoms(f"H{len(r)}", positions=r, cell=[1, 1, 0], pbc=[True, True, False])
    with pytest.raises(ValueError, match="1D"):
        WVTRelaxation(atoms, lambda x: np.ones(len(x)), dim=1)
    atoms.pbc = False
    with pytest.raises(ValueError, match="y = 0"):
        WVTRelaxation(atoms, lambda x: np.ones(len(x)), dim=1)


# -- shared CLI habits -------------------------------------------------------------------------------------
def test_out_with_files_is_refused_unless_overwrite(square, tmp_path, capsys):
    out = tmp_path / "o"
    out.mkdir()
    (out / "mine.txt").write_text("keep")
    args = ["pack", "--boundary", str(square), "--dx", "0.2", "--max-steps-2a", "2", "--max-steps-2c", "2",
            "--out", str(out)]
    assert main(args) == 2
    assert "--overwrite" in _one_line_error(capsys)
    assert main(args + ["--overwrite"]) == 0
    assert (out / "mine.txt").read_text() == "keep" and (out / "summary.json").is_file()


def test_pack_draws_no_progress_bar_into_a_log(square, tmp_path):
    """Run as a user would with output redirected: no bar (issue: 24-95 KB of bar in logs)."""
    run = subprocess.run([sys.executable, "-m", "ase_sphrelax.cli", "pack", "--boundary", str(square), "--dx", "0.2",
                          "--max-steps-2a", "30", "--max-steps-2c", "30", "--out", str(tmp_path / "o")],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    assert "BIPI step" not in run.stderr and "\r" not in run.stderr


@pytest.mark.parametrize("command", ["relax", "pack", "density", "sample", "lattice"])
def test_every_command_has_the_shared_options(command, capsys):
    with pytest.raises(SystemExit):
        main([command, "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "--progress, --no-progress" in text
    if command != "lattice":  # lattice prints its report, it writes no folder
        assert "--overwrite" in text
        assert "; default sphrelax_" in text or "; default sample_out" in text


@pytest.mark.parametrize("command", ["relax", "pack"])
def test_summary_records_arguments_seed_version_commit_and_converged(command, square, tmp_path):
    from ase_sphrelax import __version__

    out = tmp_path / "o"
    if command == "relax":
        args = ["relax", "--dx", "0.05", "--steps", "5", "--seed", "7"]
    else:
        args = ["pack", "--boundary", str(square), "--dx", "0.2", "--max-steps-2a", "2", "--max-steps-2c", "2"]
    assert main(args + ["--out", str(out)]) == 0
    s = _summary(out)
    assert s["version"] == __version__ and s["command"] == command
    assert s["git_commit"] is None or len(s["git_commit"]) == 40
    assert s["arguments"]["out"] == str(out) and "seed" in s
    assert s["converged"] is False and s["convergence_reason"]
    if command == "relax":
        assert s["seed"] == 7 and s["arguments"]["steps"] == 5


def test_relax_that_misses_fmax_within_the_default_steps_exits_3(tmp_path, monkeypatch, capsys):
    import ase_sphrelax.cli.relax as relax

    monkeypatch.setattr(relax, "DEFAULT_STEPS", 3)
    out = tmp_path / "o"
    assert main(["relax", "--dx", "0.05", "--fmax", "1e-12", "--out", str(out)]) == 3
    assert _summary(out)["converged"] is False
    assert "not converged" in capsys.readouterr().err


# -- the MPI worker's arguments: JSON, not a pickle --------------------------------------------------------
def test_worker_arguments_are_json_and_rebuild_the_model(tmp_path):
    from ase_sphrelax.domains import Box, Circle
    from ase_sphrelax.models.fan import FanModel
    from lammps_io.worker_args import WORKER_FILE, read_worker_args, write_worker_args

    r_pc = np.random.default_rng(1).uniform(-1.2, 1.2, (50, 2))
    for domain in (Circle((0.1, 0.2), 1.0), Box((-1, -1), (1, 1)), None):
        model = FanModel(0.26, 0.1, domain, 2)
        write_worker_args(tmp_path, model, 0.01, 2)
        json.loads((tmp_path / WORKER_FILE).read_text())  # plain JSON
        kwargs = read_worker_args(tmp_path)
        assert kwargs["v0"] == 0.01 and kwargs["nthreads"] == 2
        if domain is not None:
            e0, f0 = model.boundary(r_pc, 0.01)
            e1, f1 = kwargs["model"].boundary(r_pc, 0.01)
            np.testing.assert_array_equal(e0, e1)
            np.testing.assert_array_equal(f0, f1)
    assert not list(tmp_path.glob("*.pkl"))


def test_worker_reads_no_pickle():
    import inspect

    import lammps_io._worker as worker
    import lammps_io.relaxation as relaxation

    for module in (worker, relaxation):
        assert "pickle" not in inspect.getsource(module)


def test_export_refuses_to_replace_a_file_unless_overwrite(tmp_path, capsys):
    from ase_sphrelax.build import periodic_box

    atoms = periodic_box((4, 3), dx=0.5, dim=2, jitter=0.1, seed=0)
    atoms.write(tmp_path / "in.extxyz")
    out = tmp_path / "out.data"
    out.write_text("mine")
    assert main(["export", str(tmp_path / "in.extxyz"), str(out)]) == 2
    assert "--overwrite" in _one_line_error(capsys) and out.read_text() == "mine"
    assert main(["export", str(tmp_path / "in.extxyz"), str(out), "--overwrite", "--no-progress"]) == 0
    assert out.read_text() != "mine"
