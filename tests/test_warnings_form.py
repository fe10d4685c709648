"""Warnings in one documented form (issue 31 item 7): one class in Python, one line on the command line.

* every ``warnings.warn(`` in ``ase_sphrelax`` and ``lammps_io`` passes a class that derives from
  :class:`ase_sphrelax.SphrelaxWarning` (a static check over the source);
* ``sphrelax COMMAND`` prints a package warning as ``sphrelax COMMAND: warning: MESSAGE``, one line, without
  the file path and line of Python's default form.
"""
import ast
import os
import subprocess
import sys
import warnings
from pathlib import Path

import pytest

import ase_sphrelax
from ase_sphrelax.checks import SphrelaxWarning

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("ase_sphrelax", "lammps_io")


def _sources():
    for package in PACKAGES:
        yield from sorted((ROOT / package).rglob("*.py"))


def _classes():
    """``{class name: [base names]}`` of every class defined in the packages."""
    bases = {}
    for path in _sources():
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ClassDef):
                bases.setdefault(node.name, []).extend(ast.unparse(b).split(".")[-1] for b in node.bases)
    return bases


def _derives(name, bases, seen=()):
    if name == "SphrelaxWarning":
        return True
    return any(b not in seen and _derives(b, bases, seen + (name,)) for b in bases.get(name, []))


def _warn_calls():
    """(path, line, category source) of every ``warnings.warn(...)`` / ``warn(...)`` call."""
    for path in _sources():
        for node in ast.walk(ast.parse(path.read_text())):
            if not isinstance(node, ast.Call):
                continue
            f = node.func
            name = f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", None)
            if name != "warn" or (isinstance(f, ast.Attribute) and ast.unparse(f.value) != "warnings"):
                continue
            category = node.args[1] if len(node.args) > 1 else next(
                (k.value for k in node.keywords if k.arg == "category"), None)
            yield path.relative_to(ROOT), node.lineno, None if category is None else ast.unparse(category)


def test_every_package_warning_is_a_sphrelax_warning():
    bases = _classes()
    calls = list(_warn_calls())
    assert len(calls) >= 10  # the scan finds the calls (12 on 2026-12-05)
    bad = [f"{p}:{line} ({c})" for p, line, c in calls if c is None or not _derives(c.split(".")[-1], bases)]
    assert not bad, "warnings.warn without a SphrelaxWarning (sub)class: " + ", ".join(bad)


def test_the_class_is_exported_and_the_specific_ones_derive_from_it():
    from ase_sphrelax.boundary.periodic import PeriodicFacesWarning
    from ase_sphrelax.boundary.segments import OrientationWarning
    from ase_sphrelax.checks import NotConvergedWarning, PluginWarning, SpacingWarning, SPHScaleWarning
    from ase_sphrelax.drivers.step_scale import NothingRelaxedWarning
    from ase_sphrelax.models.fan import ParticlesOutsideWarning

    assert ase_sphrelax.SphrelaxWarning is SphrelaxWarning and issubclass(SphrelaxWarning, UserWarning)
    for cls in (PeriodicFacesWarning, OrientationWarning, NotConvergedWarning, SpacingWarning, SPHScaleWarning,
                NothingRelaxedWarning, ParticlesOutsideWarning, PluginWarning):
        assert issubclass(cls, SphrelaxWarning), cls
    assert issubclass(PluginWarning, RuntimeWarning)  # what it was before: filters on RuntimeWarning still work
    with pytest.warns(SphrelaxWarning, match="runs clockwise"):
        from ase_sphrelax.boundary import BoundarySegments

        BoundarySegments.from_vertices([[[0, 0], [0, 1], [1, 1], [1, 0]]])


def test_cli_prints_warnings_as_one_line(tmp_path):
    """A clockwise outer loop (OrientationWarning) through ``sphrelax pack``: one line, the documented form (the
    run then stops at a usage error, before any packing)."""
    edges = tmp_path / "cw.edges"
    loop = [(0, 0), (0, 1), (1, 1), (1, 0)]
    edges.write_text("".join(f"{a[0]} {a[1]} {b[0]} {b[1]}\n" for a, b in zip(loop, loop[1:] + loop[:1])))
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]),
               PYTHONWARNINGS="")
    done = subprocess.run([sys.executable, "-m", "ase_sphrelax.cli", "pack", "--boundary", str(edges), "--dx", "0.1",
                           "--periodic", "q", "--no-progress", "--out", str(tmp_path / "o")],
                          capture_output=True, text=True, env=env, timeout=600)
    assert done.returncode == 2, done.stderr[-2000:]
    lines = [ln for ln in done.stderr.splitlines() if "clockwise" in ln]
    assert len(lines) == 1 and lines[0].startswith("sphrelax pack: warning: "), done.stderr
    assert ".py" not in done.stderr and "Warning:" not in done.stderr and "warnings.warn" not in done.stderr


def test_main_restores_the_format_and_callers_still_record(monkeypatch):
    """``main`` formats through ``warnings.formatwarning`` only while it runs; ``pytest.warns`` still records."""
    from ase_sphrelax.cli import main, table

    def run(args):
        warnings.warn("probe from a command", SphrelaxWarning)
        assert warnings.formatwarning("a\n b", SphrelaxWarning, "x.py", 1) == "sphrelax table: warning: a b\n"
        return 0

    monkeypatch.setattr(table, "run", run)
    before = warnings.formatwarning
    with pytest.warns(SphrelaxWarning, match="probe from a command"):
        assert main(["table"]) == 0
    assert warnings.formatwarning is before
