"""sphrelax pack --method bipi (issue 7 item 9): outputs, metrics, usage errors (exit 2, one line)."""
import json
import subprocess
import sys

import numpy as np
import pytest
from ase.io import read

from ase_sphrelax.cli import main


def sphrelax(*args):
    return subprocess.run([sys.executable, "-m", "ase_sphrelax.cli", *args], capture_output=True, text=True,
                          timeout=600)


def test_pack_trapezoid_writes_outputs(geometries, tmp_path, capsys):
    out = tmp_path / "out"
    code = main(["pack", "--method", "bipi", "--boundary", str(geometries / "TrapezoidalTank.edges"), "--dx", "0.05",
                 "--h", "4", "--out", str(out), "--max-steps-2a", "60", "--max-steps-2c", "60"])
    assert code == 0
    text = capsys.readouterr().out
    assert "Step 2a" in text and "wall time" in text and "particles outside" in text
    atoms = read(out / "packed.extxyz")
    data = json.loads((out / "summary.json").read_text())
    s = data["summary"]
    assert s["n_particles"] == len(atoms) and s["n_outside"] == 0
    assert s["h"] == pytest.approx(0.2) and s["h_over_dx_paper"] == pytest.approx(2.0)
    assert len(data["history"]) == s["iterations_2a"] + s["iterations_2c"]
    assert (out / "packed.png").stat().st_size > 1000 and (out / "history.png").stat().st_size > 1000
    assert np.all(atoms.positions[:, 2] == 0)


def test_pack_paper_ratio_and_stl(tmp_path, capsys):
    trimesh = pytest.importorskip("trimesh")
    path = tmp_path / "cube.stl"
    trimesh.creation.box(extents=(1, 1, 1)).export(path)
    out = tmp_path / "cube"
    assert main(["pack", "--boundary", str(path), "--dx", "0.2", "--h-paper", "1.5", "--out", str(out),
                 "--max-steps-2a", "5", "--max-steps-2c", "5"]) == 0
    s = json.loads((out / "summary.json").read_text())["summary"]
    assert s["h_over_dx"] == pytest.approx(3.0) and s["n_outside"] == 0


@pytest.mark.parametrize("args,message", [
    (["--dx", "5"], "larger than the shape"),
    (["--dx", "0.05", "--h", "0.5"], "h must be at least dx"),
    (["--dx", "-1"], "positive"),
    (["--dx", "0.05", "--h", "4", "--h-paper", "2"], "not allowed with"),
])
def test_pack_usage_errors(geometries, args, message):
    result = sphrelax("pack", "--boundary", str(geometries / "TrapezoidalTank.edges"), *args)
    assert result.returncode == 2
    assert message in result.stderr
    assert "Traceback" not in result.stderr


def test_pack_bad_boundary_files(tmp_path):
    missing = sphrelax("pack", "--boundary", str(tmp_path / "none.edges"), "--dx", "0.1")
    assert missing.returncode == 2 and "no such file" in missing.stderr
    bad = tmp_path / "open.edges"
    bad.write_text("0 0 1 0\n1 0 1 1\n1 1 0 1\n")
    result = sphrelax("pack", "--boundary", str(bad), "--dx", "0.1")
    assert result.returncode == 2 and "open.edges" in result.stderr and "not closed" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


def test_pack_momentum_reaches_step_2c_and_is_checked(geometries, tmp_path, capsys):
    """--momentum BETA: the heavy-ball Step 2c of BIPIPacker(momentum=BETA); 0 is the paper's rule, BETA >= 1 refused."""
    histories = {}
    for beta in ("0", "0.9"):
        out = tmp_path / f"m{beta}"
        assert main(["pack", "--boundary", str(geometries / "TrapezoidalTank.edges"), "--dx", "0.05", "--h", "4",
                     "--out", str(out), "--max-steps-2a", "20", "--max-steps-2c", "20", "--momentum", beta]) == 0
        data = json.loads((out / "summary.json").read_text())
        histories[beta] = data["history"]
    gradc = {beta: [row["gradc_avg"] for row in history] for beta, history in histories.items()}
    n_2a = 20
    assert gradc["0"][:n_2a] == gradc["0.9"][:n_2a]  # Step 2a untouched
    assert gradc["0"][n_2a + 1:] != gradc["0.9"][n_2a + 1:]
    bad = sphrelax("pack", "--boundary", str(geometries / "TrapezoidalTank.edges"), "--dx", "0.05", "--momentum", "1")
    assert bad.returncode == 2 and "[0, 1)" in bad.stderr and "Traceback" not in bad.stderr
