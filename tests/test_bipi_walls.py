"""Wall particles beside a BIPI packing (issue 17 item 3): kinds through extxyz and LAMMPS data, the band's extent."""
import json

import numpy as np
import pytest
from ase.io import read, write

from ase_sphrelax.boundary import BoundarySegments
from ase_sphrelax.domains import Polygon
from ase_sphrelax.drivers.bipi_packer import FLUID, WALL, add_walls, initial_fill, wall_layers, wall_particles

WEDGE_TANK = [[0.0, 0.0], [0.4, 0.0], [0.5, 0.1], [0.6, 0.0], [1.0, 0.0], [1.0, 0.5], [0.0, 0.5]]


def _boundary(loop=WEDGE_TANK):
    return BoundarySegments.from_polygon(Polygon([loop]))


@pytest.mark.parametrize("layers", [1, 2, 4])
def test_walls_outside_within_band(layers):
    boundary, dx = _boundary(), 0.05
    walls = wall_particles(boundary, dx, layers=layers)
    phi = boundary.domain.phi(walls.positions[:, :2])
    assert len(walls) > 0 and np.all(walls.arrays["type"] == WALL)
    assert np.all(phi > 0) and phi.max() <= layers * dx * (1 + 1e-12)
    assert phi.max() <= (layers + 1) * dx
    assert np.all(walls.positions[:, 2] == 0)


def test_walls_are_the_grid_band():
    """Brute force: every Step-1 grid centre with 0 < phi <= k dx, and no other point."""
    boundary, dx, k = _boundary(), 0.05, 3
    walls = wall_particles(boundary, dx, layers=k)
    axes = [(np.arange(-20, 40) + 0.5) * dx] * 2
    gx, gy = np.meshgrid(*axes, indexing="ij")
    r_pd = np.stack([gx.ravel(), gy.ravel()], axis=1)
    phi = boundary.domain.phi(r_pd)
    expected = r_pd[(phi > 0) & (phi <= k * dx)]
    got = walls.positions[:, :2]
    key = lambda r: set(map(tuple, np.round(r / dx - 0.5).astype(int)))  # noqa: E731
    assert key(got) == key(expected) and len(got) == len(expected)


def test_default_layers_cover_the_support():
    assert wall_layers(0.13, 0.05) == 3 and wall_layers(0.1, 0.05) == 2 and wall_layers(0.2 + 1e-15, 0.05) == 4
    walls = wall_particles(_boundary(), 0.05, h=0.13)
    assert walls.info["wall_layers"] == 3
    with pytest.raises(ValueError, match="layers"):
        wall_particles(_boundary(), 0.05)
    with pytest.raises(ValueError, match="layers"):
        wall_particles(_boundary(), 0.05, layers=0)


def test_fluid_and_walls_do_not_overlap_and_keep_filter():
    boundary, dx = _boundary(), 0.05
    fluid = initial_fill(boundary, dx)
    both = add_walls(fluid, boundary, dx, layers=2, keep=lambda r: r[:, 1] < 0.5)
    t = both.arrays["type"]
    assert np.all(t[: len(fluid)] == FLUID) and np.all(t[len(fluid):] == WALL)
    assert both.info["n_fluid"] == len(fluid) and both.info["n_wall"] == int((t == WALL).sum())
    assert np.all(both.positions[t == WALL, 1] < 0.5)
    d = np.linalg.norm(both.positions[:, None, :] - both.positions[None, :, :], axis=2)
    np.fill_diagonal(d, np.inf)
    assert d.min() > 0.5 * dx


def test_types_survive_extxyz_and_lammps_data(tmp_path):
    from lammps_io import write_data

    boundary, dx = _boundary(), 0.05
    both = add_walls(initial_fill(boundary, dx), boundary, dx, layers=2)
    write(tmp_path / "p.extxyz", both, format="extxyz")
    back = read(tmp_path / "p.extxyz")
    assert np.array_equal(back.arrays["type"], both.arrays["type"])
    np.testing.assert_allclose(back.positions, both.positions, atol=1e-12)
    write_data(both, tmp_path / "p.data", atom_style="atomic", dim=2, margin=dx)
    text = (tmp_path / "p.data").read_text()
    assert "2 atom types" in text
    rows = text.split("Atoms")[1].strip().splitlines()[1:]
    rows = [r.split() for r in rows if r.strip()]
    ids = np.array([int(r[0]) for r in rows])
    types = np.array([int(r[1]) for r in rows])[np.argsort(ids)]
    assert len(types) == len(both) and np.array_equal(types, both.arrays["type"])


def test_cli_pack_walls(geometries, tmp_path):
    from ase_sphrelax.cli import main

    out = tmp_path / "out"
    code = main(["pack", "--boundary", str(geometries / "TrapezoidalTank.edges"), "--dx", "0.05", "--h", "2.6",
                 "--out", str(out), "--max-steps-2a", "5", "--max-steps-2c", "5", "--walls", "2", "--no-progress"])
    assert code == 0
    atoms = read(out / "packed.extxyz")
    t = atoms.arrays["type"]
    s = json.loads((out / "summary.json").read_text())["summary"]
    assert s["n_wall"] == int((t == WALL).sum()) > 0 and s["wall_layers"] == 2
    assert s["n_particles"] == int((t == FLUID).sum())
    boundary = BoundarySegments.from_edges(geometries / "TrapezoidalTank.edges")
    phi = boundary.domain.phi(atoms.positions[:, :2])
    assert np.all(phi[t == WALL] > 0) and phi[t == WALL].max() <= 3 * 0.05 and np.all(phi[t == FLUID] < 0)


def test_wedge_tank_example_walls_stay_below_the_surface():
    """examples/bipi_sph.py's tank: walls outside floor, wedge and sides only, none at or above the water."""
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "examples" / "bipi_sph.py"
    spec = importlib.util.spec_from_file_location("bipi_sph", path)
    example = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(example)
    boundary, dx = example.wedge_tank(), 0.05
    h = example.H_OVER_DX * dx
    both = example.with_walls(initial_fill(boundary, dx), boundary, dx, h, example.DEPTH)
    t = both.arrays["type"]
    phi = boundary.domain.phi(both.positions[:, :2])
    assert np.all(phi[t == FLUID] < 0) and np.all(phi[t == WALL] > 0) and phi[t == WALL].max() <= 4 * dx * (1 + 1e-12)
    assert both.positions[t == WALL, 1].max() < example.DEPTH
    tip = np.array([0.5 * example.WIDTH, example.WEDGE_HEIGHT])
    assert boundary.domain.phi(tip[None, :])[0] == pytest.approx(0.0, abs=1e-12)  # the wedge's tip is on the boundary
