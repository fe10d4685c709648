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


# -- registry, usage errors and start-up ------------------------------------------------------
import ast
import importlib
import os
import subprocess
import sys
from pathlib import Path

import ase_sphrelax
from ase_sphrelax.cli import UsageError, registry, usage_errors

PLUGIN = '''
"""A plug-in package registering sphrelax commands and a relax method by entry point."""
from ase_sphrelax.cli import UsageError, usage_errors


class Hello:
    """say hello from a plug-in (100% fake)

    Registered in ase_sphrelax.commands by this fake distribution.
    """

    @staticmethod
    def add_arguments(parser):
        parser.add_argument("--name", default="world")

    @staticmethod
    def run(args):
        print(f"hello {args.name}")


class Boom:
    """fail in the set-up phase, with a UsageError, or in the run phase"""

    @staticmethod
    def add_arguments(parser):
        parser.add_argument("--where", choices=("setup", "usage", "run"), default="run")

    @staticmethod
    def run(args):
        if args.where == "setup":
            with usage_errors():
                raise ValueError("bad value\\nof --where")
        if args.where == "usage":
            raise UsageError("no good")
        raise ValueError("internal failure in the run phase")


class ToyMethod:
    """Fan's model with h scaled by --toy-scale (a relax method from a plug-in)"""

    energy_label = "toy energy"

    @staticmethod
    def add_arguments(parser):
        parser.add_argument("--toy-scale", type=float, default=1.0)

    @staticmethod
    def calculator(scene, h, args):
        from ase_sphrelax import FanCalculator

        return FanCalculator(h=h * args.toy_scale, dx=scene.dx, domain=scene.domain, dim=scene.dim)
'''

ENTRY_POINTS = '''
[ase_sphrelax.commands]
hello = fake_sphrelax_plugin:Hello
boom = fake_sphrelax_plugin:Boom
broken = fake_sphrelax_plugin:DoesNotExist
relax = fake_sphrelax_plugin:Hello

[ase_sphrelax.methods.relax]
toy = fake_sphrelax_plugin:ToyMethod
'''


@pytest.fixture
def plugin_dir(tmp_path_factory):
    """A fake installed distribution (module + dist-info with entry points) in a folder for sys.path."""
    root = tmp_path_factory.mktemp("plugin")
    (root / "fake_sphrelax_plugin.py").write_text(PLUGIN)
    info = root / "fake_sphrelax_plugin-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: fake-sphrelax-plugin\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(ENTRY_POINTS)
    return root


@pytest.fixture
def plugin(plugin_dir, monkeypatch):
    monkeypatch.syspath_prepend(str(plugin_dir))
    yield plugin_dir
    sys.modules.pop("fake_sphrelax_plugin", None)


def sphrelax(args, plugin_path=None, code=None):
    """Run ``python -m ase_sphrelax.cli ARGS`` (or ``python -c CODE``) in a fresh interpreter."""
    env = dict(os.environ)
    if plugin_path is not None:
        env["PYTHONPATH"] = os.pathsep.join([str(plugin_path)] + env.get("PYTHONPATH", "").split(os.pathsep))
    cmd = [sys.executable, "-c", code] if code else [sys.executable, "-m", "ase_sphrelax.cli", *args]
    return subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=300)


def test_registered_command_is_listed_and_runs(plugin, capsys):
    with pytest.warns(RuntimeWarning) as caught:
        found = registry.commands()
    messages = " ".join(str(w.message) for w in caught)
    assert "'broken'" in messages and "skipped" in messages  # a broken plug-in does not take the others down
    assert "'relax'" in messages and "already ase_sphrelax.cli.relax" in messages
    assert list(found)[:3] == ["relax", "lattice", "table"]  # built-ins first, and they win
    assert found["relax"] is importlib.import_module("ase_sphrelax.cli.relax")
    assert {"hello", "boom", "export"} <= set(found) and "broken" not in found
    with pytest.warns(RuntimeWarning), pytest.raises(SystemExit):
        main(["--help"])
    assert "say hello from a plug-in (100% fake)" in capsys.readouterr().out
    with pytest.warns(RuntimeWarning):
        assert main(["hello", "--name", "sph"]) == 0
    assert capsys.readouterr().out == "hello sph\n"


def test_registered_relax_method_dispatches(plugin, tmp_path, capsys):
    with pytest.warns(RuntimeWarning):
        assert "toy" in registry.methods("relax")
        code = main(["relax", "--method", "toy", "--toy-scale", "1.5", "--dx", "0.05", "--steps", "3",
                     "--out", str(tmp_path)])
    assert code == 0
    assert "toy energy:" in capsys.readouterr().out
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["method"] == "toy" and summary["steps"] == 3
    atoms = read(tmp_path / "relaxed.extxyz")
    assert atoms.info["h"] == pytest.approx(2.6 * 0.05)  # the scene's h; the toy scales its own copy


def test_relax_method_fan_explicit(tmp_path, capsys):
    assert main(["relax", "--method", "fan", "--dx", "0.05", "--steps", "5", "--out", str(tmp_path)]) == 0
    printed = capsys.readouterr().out
    assert "method = fan, engine = ase, optimizer = fan" in printed
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert (summary["method"], summary["engine"], summary["steps"]) == ("fan", "ase", 5)
    assert summary["energy_after"] < summary["energy_before"]


def test_methods_and_engines_of_the_registry():
    from ase_sphrelax.cli.relax import AseEngine, FanMethod

    assert registry.methods("relax")["fan"] is FanMethod
    assert registry.engines()["ase"] is AseEngine
    assert registry.methods("no-such-command") == {}
    assert registry.help_texts(FanMethod)[0].startswith("Fan et al.'s total error")


def test_usage_error_exits_2_with_one_line(plugin_dir):
    for args, message in [(["boom", "--where", "setup"], "sphrelax boom: error: bad value of --where"),
                          (["boom", "--where", "usage"], "sphrelax boom: error: no good"),
                          (["relax", "--domain", "hexagon"], "sphrelax relax: error: --domain must be one of")]:
        done = sphrelax(args, plugin_dir)
        assert done.returncode == 2, done.stderr
        lines = [line for line in done.stderr.splitlines()
                 if not line.startswith(f"sphrelax {args[0]}: warning: ")]  # the broken plug-in's warnings, one line each
        assert len(lines) == 1 and lines[0].startswith(message), done.stderr
        assert "Traceback" not in done.stderr


def test_internal_error_keeps_its_traceback(plugin_dir):
    done = sphrelax(["boom", "--where", "run"], plugin_dir)
    assert done.returncode == 1
    assert "Traceback (most recent call last)" in done.stderr
    assert done.stderr.rstrip().endswith("ValueError: internal failure in the run phase")


def test_internal_error_in_relax_is_not_a_usage_error(tmp_path, monkeypatch):
    """A ValueError after the set-up phase propagates (no exit 2)."""
    import ase_sphrelax.drivers.optimizers as optimizers

    def broken(*args, **kwargs):
        raise ValueError("a bug in the optimiser")

    monkeypatch.setattr(optimizers, "make_optimizer", broken)
    with pytest.raises(ValueError, match="a bug in the optimiser"):
        main(["relax", "--dx", "0.05", "--steps", "2", "--out", str(tmp_path)])


def test_usage_errors_converts_only_setup_errors():
    for error in (ValueError("v"), TypeError("t"), FileNotFoundError("f")):
        with pytest.raises(UsageError, match=str(error)), usage_errors():
            raise error
    with pytest.raises(KeyError), usage_errors():
        raise KeyError("internal")


def test_relax_bad_out_and_engine_method_mismatch(plugin, tmp_path, capsys):
    (tmp_path / "file").write_text("")
    with pytest.warns(RuntimeWarning):
        assert main(["relax", "--out", str(tmp_path / "file")]) == 2
    assert "is not a folder" in capsys.readouterr().err
    with pytest.warns(RuntimeWarning):
        assert main(["relax", "--engine", "lammps", "--method", "toy", "--out", str(tmp_path)]) == 2
    assert "--engine lammps supports --method fan" in capsys.readouterr().err


HELP_IMPORTS = """
import sys
from ase_sphrelax.cli import main
try:
    main({argv!r})
except SystemExit:
    pass
heavy = [name for name in ("numba", "scipy", "lammps", "matplotlib", "ase.optimize", "ase.io", "spglib",
                           "lammps_io.calculator", "lammps_io.relaxation", "ase_sphrelax.kernels")
         if name in sys.modules]
print("HEAVY", heavy)
"""


@pytest.mark.parametrize("argv", [["--help"], ["relax", "--help"], ["export", "--help"]])
def test_help_loads_no_numba(argv):
    done = sphrelax(None, code=HELP_IMPORTS.format(argv=argv))
    assert done.returncode == 0, done.stderr
    assert "usage: sphrelax" in done.stdout
    assert done.stdout.splitlines()[-1] == "HEAVY []"


def test_package_import_is_light_and_lazy_names_resolve():
    done = sphrelax(None, code="import sys, ase_sphrelax, lammps_io; print('numba' in sys.modules)")
    assert done.stdout.strip() == "False", done.stderr
    import ase_sphrelax.analysis
    import ase_sphrelax.drivers
    import lammps_io

    for package in (ase_sphrelax, ase_sphrelax.drivers, ase_sphrelax.analysis, lammps_io):
        for name in package.__all__:
            assert getattr(package, name) is not None, (package.__name__, name)
        assert set(package.__all__) <= set(dir(package))
        with pytest.raises(AttributeError, match="no attribute 'nope'"):
            package.nope  # noqa: B018
    assert callable(lammps_io.sph_at_rest)


def test_no_import_of_lammps_io_in_ase_sphrelax():
    """lammps_io depends on ase_sphrelax, never the reverse (its CLI plugs in by entry point)."""
    root = Path(ase_sphrelax.__file__).parent
    offenders = []
    for path in root.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            names = []
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0:
                names = [node.module or ""]
            elif isinstance(node, ast.Constant) and isinstance(node.value, str):
                names = [node.value] if node.value.startswith("lammps_io.") and " " not in node.value else []
            offenders += [f"{path.relative_to(root)}: {name}" for name in names if name.split(".")[0] == "lammps_io"]
    assert offenders == []


def test_optimizer_names_have_one_source():
    """OPTIMIZERS (drivers/optimizers.py) is the only literal list of optimiser names in the package."""
    from ase_sphrelax.drivers.optimizers import OPTIMIZERS

    relax = next(a for a in ase_sphrelax.cli.build_parser()._actions if a.dest == "command").choices["relax"]
    assert tuple(next(a for a in relax._actions if a.dest == "optimizer").choices) == OPTIMIZERS
    root = Path(ase_sphrelax.__file__).parent
    lists = []
    for path in root.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.Tuple, ast.List, ast.Set)):
                values = {e.value for e in node.elts if isinstance(e, ast.Constant)}
                if {"fire", "lbfgs"} <= values:
                    lists.append(str(path.relative_to(root)))
    assert lists == ["drivers/optimizers.py"]
