"""The data files the documentation names ship in the package: ``sphrelax data`` and ``ase_sphrelax.data``."""
from __future__ import annotations

import tomllib
from pathlib import Path

import pytest

from ase_sphrelax import data
from ase_sphrelax.cli import main

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ["airfoil.edges", "bunny.edges", "tank.edges"]


def test_names_and_paths():
    assert data.names() == SHIPPED
    for name in SHIPPED:
        assert data.path(name).is_file() and data.path(name).stat().st_size > 0
    with pytest.raises(ValueError, match="name must be one of"):
        data.path("nope.edges")


def test_package_data_is_declared():
    """The edge files are installed with the package (a wheel, not only this checkout)."""
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())
    assert "*.edges" in config["tool"]["setuptools"]["package-data"]["ase_sphrelax.data"]


def test_tank_is_the_bipi_trapezoid():
    """tank.edges is the BIPI paper's trapezoid (0,1) (0,0) (1,0) (1.5,1): counter-clockwise, area 1.25."""
    import numpy as np

    from ase_sphrelax.boundary import BoundarySegments

    edges = np.loadtxt(data.path("tank.edges"))
    assert {tuple(p) for p in edges[:, :2]} == {(0, 1), (0, 0), (1, 0), (1.5, 1)}
    area = 0.5 * np.sum(edges[:, 0] * edges[:, 3] - edges[:, 2] * edges[:, 1])
    assert area == 1.25
    assert BoundarySegments.from_edges(data.path("tank.edges")).domain.phi(np.array([[0.5, 0.5, 0.0]]))[0] < 0


def test_cli_lists_and_copies(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["data", "--list"]) == 0
    assert capsys.readouterr().out.split() == SHIPPED
    assert main(["data", "tank.edges"]) == 0
    assert (tmp_path / "tank.edges").read_text() == data.path("tank.edges").read_text()
    (tmp_path / "sub").mkdir()
    assert main(["data", "bunny.edges", "--out", "sub"]) == 0
    assert (tmp_path / "sub" / "bunny.edges").exists()
    assert main(["data", "airfoil.edges", "--out", "wing.edges"]) == 0
    assert (tmp_path / "wing.edges").exists()


@pytest.mark.parametrize("args, message", [
    (["data"], "NAME is required"),
    (["data", "nope.edges"], "name must be one of"),
    (["data", "tank.edges"], "exists (pass --overwrite)"),
])
def test_cli_usage_errors(tmp_path, monkeypatch, capsys, args, message):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "tank.edges").write_text("x")
    assert main(args) == 2
    assert message in capsys.readouterr().err
    assert (tmp_path / "tank.edges").read_text() == "x"  # never replaced without --overwrite
