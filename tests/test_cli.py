"""sphrelax relax: the main job's outputs, options and bad-input messages."""
import json

import numpy as np
import pytest
from ase.io import read

from ase_sphrelax.cli import main
from ase_sphrelax.cli.scene import make_scene


def test_default_scene_is_fans_appendix_a_circle():
    domain, dx, atoms = make_scene("circle")
    assert dx == 1 / 256 and domain.radius == 0.2 and np.allclose(domain.center, (0.5, 0.5))
    assert len(atoms) == 8224  # cell centres inside the circle (the paper quotes 8186, see build.fill)


def test_relax_writes_extxyz_png_and_summary(tmp_path, capsys):
    out = tmp_path / "run"
    code = main(["relax", "--dx", str(1 / 48), "--steps", "30", "--out", str(out), "--seed", "3"])
    assert code == 0
    printed = capsys.readouterr().out
    assert "total error E" in printed and "wall time" in printed and "mean |Σ V W - 1|" in printed
    atoms = read(out / "relaxed.extxyz")
    assert len(atoms) > 200 and "volume" in atoms.arrays and "phi" in atoms.arrays
    assert (out / "relaxed.png").stat().st_size > 10_000
    summary = json.loads((out / "summary.json").read_text())
    assert summary["steps"] == 30 and summary["energy_after"] < summary["energy_before"]


@pytest.mark.parametrize("args", [["--optimizer", "fire"], ["--optimizer", "lbfgs"], ["--domain", "box"],
                                  ["--domain", "periodic", "--dx", "0.05"], ["--domain", "sphere", "--dx", "0.05"]])
def test_relax_options(tmp_path, args):
    base = ["relax", "--steps", "10", "--out", str(tmp_path)]
    if "--dx" not in args:
        base += ["--dx", str(1 / 40)]
    assert main(base + args) == 0


def test_relax_on_an_edge_file(tmp_path, geometries):
    assert main(["relax", "--domain", str(geometries / "TrapezoidalTank.edges"), "--dx", "0.05",
                 "--steps", "10", "--out", str(tmp_path)]) == 0


@pytest.mark.parametrize("args, message", [
    (["--domain", "hexagon"], "--domain must be one of"),
    (["--domain", "sphere", "--dim", "2"], "does not match"),
])
def test_relax_bad_input_names_the_option(tmp_path, capsys, args, message):
    assert main(["relax", "--steps", "1", "--out", str(tmp_path)] + args) == 2
    assert message in capsys.readouterr().err


@pytest.mark.parametrize("args", [["--dx", "-1"], ["--h", "0"], ["--steps", "-3"], ["--optimizer", "sgd"]])
def test_relax_rejects_bad_numbers_before_work(args):
    with pytest.raises(SystemExit):
        main(["relax"] + args)
