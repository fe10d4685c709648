"""sphrelax sample: outputs for built-in and module:function targets, 1D/2D/5D plots, bad input."""
import json
import sys
import textwrap

import numpy as np
import pytest
from ase.io import read

from ase_sphrelax.cli import main


def test_sample_a_builtin_target(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["sample", "--target", "donut", "--n", "200", "--steps", "60", "--variant", "classic", "--out",
                 str(out), "--no-progress"]) == 0  # classic: 60 SPH steps, a score at every one (n_score below)
    assert "200 samples in 2D" in capsys.readouterr().out
    x = np.load(out / "samples.npy")
    assert x.shape == (200, 2) and np.all(np.isfinite(x))
    atoms = read(out / "samples.extxyz")
    np.testing.assert_allclose(atoms.positions[:, :2], x, rtol=1e-6, atol=1e-7)  # extxyz: %16.8f
    np.testing.assert_allclose(atoms.arrays["sample"], x, rtol=1e-6, atol=1e-7)
    summary = json.loads((out / "trace.json").read_text())
    assert summary["info"]["formulation"] == "force" and summary["n_score"] == 200 * 61
    assert len(summary["trace"]["step"]) == len(summary["trace"]["kinetic"]) > 2
    assert (out / "samples.png").stat().st_size > 10_000


@pytest.fixture
def user_module(tmp_path, monkeypatch):
    (tmp_path / "my_target.py").write_text(textwrap.dedent("""
        import numpy as np
        def log_density(x):
            return -0.5 * np.sum((x - 1.0) ** 2, axis=1)
        def score(x):
            return -(x - 1.0)
    """))
    monkeypatch.syspath_prepend(str(tmp_path))
    yield "my_target"
    sys.modules.pop("my_target", None)


@pytest.mark.parametrize("dim, with_score", [(1, False), (5, True)])
def test_sample_a_module_function(tmp_path, user_module, dim, with_score):
    out = tmp_path / f"run{dim}"
    n, steps = (60, 400) if dim == 1 else (1200, 40)
    args = ["sample", "--target", f"{user_module}:log_density", "--dim", str(dim), "--n", str(n), "--steps", str(steps),
            "--out", str(out), "--no-progress"]
    if with_score:
        args += ["--score", f"{user_module}:score"]
    assert main(args) == 0
    x = np.load(out / "samples.npy")
    assert x.shape == (n, dim)
    assert np.abs(x.mean() - 1.0) < 0.5  # moved towards the mode at 1
    summary = json.loads((out / "trace.json").read_text())
    assert (summary["n_score"] > 0) == with_score  # without a score: central differences of the density
    assert summary["n_density"] >= (0 if with_score else 2 * dim * n * steps)
    assert (out / "samples.png").stat().st_size > 5_000


@pytest.mark.parametrize("args, message", [
    (["--target", "ring8", "--dim", "3"], "does not match"),
    (["--target", "nomodule_xyz:f"], "cannot import"),
    (["--target", "nocolon"], "module:function"),
    (["--target", "os:nothing_here", "--dim", "2"], "no function"),
    (["--target", "json:dumps"], "--dim is required"),
    (["--target", "gaussian", "--score", "os:getcwd"], "only for module:function"),
    (["--target", "gaussian", "--friction", "-1"], "friction"),
    (["--target", "gaussian", "--n", "10"], "use at least"),
])
def test_bad_input_is_one_line(tmp_path, capsys, args, message):
    assert main(["sample", "--out", str(tmp_path), "--steps", "1", "--no-progress"] + args) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1


def test_bad_numbers_are_rejected_while_parsing(tmp_path):
    for args in (["--n", "-3"], ["--alpha", "0"], ["--support", "abc"]):
        with pytest.raises(SystemExit):
            main(["sample", "--target", "gaussian", "--out", str(tmp_path)] + args)
