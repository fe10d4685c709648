"""Wall particles beside a BIPI packing (issue 17 item 3): kinds through extxyz and LAMMPS data, the band's extent."""
import json

import numpy as np
import pytest
from examples_loader import load_script
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
    """reproductions/lib/bipi_sph.py's tank: walls outside floor, wedge and sides only, none at or above the water."""

    example = load_script("reproductions/lib/bipi_sph.py")
    boundary, dx = example.wedge_tank(), 0.05
    h = example.H_OVER_DX * dx
    both = example.with_walls(initial_fill(boundary, dx), boundary, dx, h, example.DEPTH)
    t = both.arrays["type"]
    phi = boundary.domain.phi(both.positions[:, :2])
    assert np.all(phi[t == FLUID] < 0) and np.all(phi[t == WALL] > 0) and phi[t == WALL].max() <= 4 * dx * (1 + 1e-12)
    assert both.positions[t == WALL, 1].max() < example.DEPTH
    tip = np.array([0.5 * example.WIDTH, example.WEDGE_HEIGHT])
    assert boundary.domain.phi(tip[None, :])[0] == pytest.approx(0.0, abs=1e-12)  # the wedge's tip is on the boundary


# -- packed wall particles (drivers/bipi_walls.py) -------------------------------------------------------------------
SQUARE = [[0.0, 0.0], [0.5, 0.0], [0.5, 0.5], [0.0, 0.5]]
CAPS = dict(max_steps_2a=400, max_steps_2c=300)


@pytest.fixture(scope="module")
def packed_square():
    from ase_sphrelax.drivers.bipi_walls import packed_wall_particles

    boundary, dx, k = _boundary(SQUARE), 0.05, 3
    return boundary, dx, k, packed_wall_particles(boundary, dx, layers=k, h=4 * dx, **CAPS)


@pytest.fixture(scope="module")
def packed_wedge():
    import shapely

    from ase_sphrelax.drivers.bipi_walls import packed_wall_particles

    boundary, dx, k = _boundary(), 0.05, 2
    clip = shapely.box(-1.0, -1.0, 2.0, 0.5)  # no wall above the water surface y = 0.5
    return boundary, dx, k, packed_wall_particles(boundary, dx, layers=k, h=4 * dx, clip=clip, **CAPS)


def test_wall_band_is_the_offset_set():
    """The band is {0 < phi <= k dx} up to the chords of its rounded corners (brute force on random points)."""
    from ase_sphrelax.drivers.bipi_walls import wall_band

    boundary, dx, k = _boundary(), 0.05, 3
    band = wall_band(boundary, dx, layers=k)
    rng = np.random.default_rng(0)
    r = rng.uniform([-0.3, -0.3], [1.3, 0.8], size=(20000, 2))
    phi = boundary.domain.phi(r)
    chord = k * dx * (1 - np.cos(np.pi / 4 / 16))  # sagitta of a 16-segment quarter circle
    sure_in = (phi > 1e-9) & (phi < k * dx - chord - 1e-9)
    sure_out = (phi < -1e-9) | (phi > k * dx + 1e-9)
    inside = band.contains(r)
    assert inside[sure_in].all() and not inside[sure_out].any()
    square = wall_band(_boundary(SQUARE), dx, layers=k)
    exact = 4 * 0.5 * k * dx + np.pi * (k * dx) ** 2
    assert square.area == pytest.approx(exact, rel=2e-3) and square.area < exact
    # the fluid's walls are edges of the band: their midpoints are on the band's boundary
    mid = 0.5 * (boundary.start_sc + boundary.end_sc)
    assert np.abs(band.domain.phi(mid)).max() < 1e-12


def test_packed_walls_outside_within_band_no_overlap(packed_square, packed_wedge):
    for boundary, dx, k, walls in (packed_square, packed_wedge):
        phi = boundary.domain.phi(walls.positions[:, :2])
        assert len(walls) > 0 and np.all(walls.arrays["type"] == WALL) and np.all(walls.positions[:, 2] == 0)
        assert phi.min() > 0.3 * dx and phi.max() <= k * dx + 1e-9
        fluid = initial_fill(boundary, dx)
        d = np.linalg.norm(walls.positions[:, None, :] - fluid.positions[None, :, :], axis=2)
        assert d.min() >= 0.5 * dx
        d = np.linalg.norm(walls.positions[:, None, :] - walls.positions[None, :, :], axis=2)
        np.fill_diagonal(d, np.inf)
        assert d.min() > 0.5 * dx
    _, _, _, walls = packed_wedge
    assert walls.positions[:, 1].max() < 0.5


def _layer_offsets(boundary, dx, walls, away):
    """phi / dx of the wall particles whose closest wall point is at least ``away`` from every vertex."""
    r = walls.positions[:, :2]
    phi, n = boundary.domain.phi_and_normal(r)
    foot = r - phi[:, None] * n[:, :2]
    v = np.concatenate(boundary.loops)
    far = np.linalg.norm(foot[:, None, :] - v[None, :, :], axis=2).min(axis=1) > away
    return phi[far] / dx


def test_packed_walls_layers_and_count_square(packed_square):
    boundary, dx, k, walls = packed_square
    offsets = _layer_offsets(boundary, dx, walls, away=(k + 1) * dx)
    layer = np.floor(offsets).astype(int)
    assert set(layer.tolist()) == set(range(k))
    assert np.abs(offsets - (layer + 0.5)).max() < 0.2  # rows parallel to the wall, (j + 1/2) dx
    counts = np.bincount(layer)  # the straight parts of the sides: as many particles in every layer
    assert counts.max() - counts.min() <= 4
    band_area = 4 * 0.5 * k * dx + np.pi * (k * dx) ** 2
    assert abs(len(walls) - band_area / dx**2) <= 0.03 * band_area / dx**2
    assert walls.info["wall_layers"] == k and walls.info["wall_mode"] == "packed"


def test_packed_walls_layers_and_count_wedge(packed_wedge):
    import shapely

    from ase_sphrelax.drivers.bipi_walls import wall_band

    boundary, dx, k, walls = packed_wedge
    offsets = _layer_offsets(boundary, dx, walls, away=(k + 1) * dx)
    layer = np.floor(offsets).astype(int)
    assert set(layer.tolist()) == set(range(k))
    assert np.abs(offsets - (layer + 0.5)).max() < 0.25
    area = wall_band(boundary, dx, layers=k, clip=shapely.box(-1.0, -1.0, 2.0, 0.5)).area
    assert abs(len(walls) - area / dx**2) <= 0.05 * area / dx**2


def test_packed_walls_types_round_trip(packed_wedge, tmp_path):
    from lammps_io import write_data

    from ase_sphrelax.drivers.bipi_walls import add_packed_walls

    boundary, dx, k, walls = packed_wedge
    fluid = initial_fill(boundary, dx)
    both = add_packed_walls(fluid, boundary, dx, walls=walls)
    t = both.arrays["type"]
    assert np.all(t[: len(fluid)] == FLUID) and np.all(t[len(fluid):] == WALL)
    assert both.info["n_fluid"] == len(fluid) and both.info["n_wall"] == len(walls)
    assert both.info["wall_mode"] == "packed"
    write(tmp_path / "p.extxyz", both, format="extxyz")
    back = read(tmp_path / "p.extxyz")
    assert np.array_equal(back.arrays["type"], t)
    np.testing.assert_allclose(back.positions, both.positions, atol=1e-7)  # extxyz writes 8 decimals
    write_data(both, tmp_path / "p.data", atom_style="atomic", dim=2, margin=dx)
    data = read(tmp_path / "p.data", format="lammps-data", atom_style="atomic", units="metal")
    assert np.array_equal(np.asarray(data.arrays["type"]), t)
    shift = data.positions[0] - both.positions[0]
    np.testing.assert_allclose(data.positions[:, :2] - shift[:2], both.positions[:, :2], atol=1e-9)


def test_packed_walls_bad_input():
    from ase_sphrelax.drivers.bipi_walls import packed_wall_particles, wall_band

    with pytest.raises(ValueError, match="layers"):
        wall_band(_boundary(), 0.05)
    with pytest.raises(ValueError, match="layers"):
        wall_band(_boundary(), 0.05, layers=0)
    with pytest.raises(ValueError, match="dx"):
        wall_band(_boundary(), -0.05, layers=2)
    import shapely

    with pytest.raises(ValueError, match="clip"):
        packed_wall_particles(_boundary(), 0.05, layers=2, clip=shapely.box(0.2, 0.2, 0.3, 0.3))


def test_cli_pack_packed_walls(geometries, tmp_path):
    from ase_sphrelax.cli import main

    out = tmp_path / "out"
    code = main(["pack", "--boundary", str(geometries / "TrapezoidalTank.edges"), "--dx", "0.05", "--h", "2.6",
                 "--out", str(out), "--max-steps-2a", "5", "--max-steps-2c", "5", "--walls", "2", "--wall-mode",
                 "packed", "--no-progress"])
    assert code == 0
    atoms = read(out / "packed.extxyz")
    t = atoms.arrays["type"]
    s = json.loads((out / "summary.json").read_text())["summary"]
    assert s["n_wall"] == int((t == WALL).sum()) > 0 and s["wall_layers"] == 2 and s["wall_mode"] == "packed"
    boundary = BoundarySegments.from_edges(geometries / "TrapezoidalTank.edges")
    phi = boundary.domain.phi(atoms.positions[:, :2])
    assert np.all(phi[t == WALL] > 0) and phi[t == WALL].max() <= 2 * 0.05 + 1e-9 and np.all(phi[t == FLUID] < 0)
    grid = sorted(map(tuple, np.round(atoms.positions[t == WALL, :2] / 0.05 - 0.5, 6)))
    assert any(abs(c - round(c)) > 1e-3 for xy in grid for c in xy)  # not the grid's cell centres
    # and on through `sphrelax export` to a LAMMPS data file: the kinds are its atom types
    assert main(["export", str(out / "packed.extxyz"), str(tmp_path / "p.data"), "--format", "lammps",
                 "--atom-style", "atomic"]) == 0
    data = read(tmp_path / "p.data", format="lammps-data", atom_style="atomic", units="metal")
    assert np.array_equal(np.asarray(data.arrays["type"]), t)


def test_coral_tank_example_geometry():
    """reproductions/lib/bipi_sph.py's case (b): one loop; the coral's trunk and tips are solid; its band covers the thin branches."""

    import shapely

    from ase_sphrelax.drivers.bipi_walls import wall_band

    example = load_script("reproductions/lib/bipi_sph.py")
    dx = 0.02
    boundary = example.coral_tank(dx)
    tank_area = 0.5 * (1.4 + 1.9) * example.CORAL_DEPTH
    assert len(boundary.loops) == 1 and 0.9 * tank_area < boundary.area < tank_area
    solid = np.array([[1.0, 0.05], [0.86, 0.24], [1.24, 0.33]])  # trunk, a fork, a tip
    assert np.all(boundary.domain.phi(solid) > 0)
    band = wall_band(boundary, dx, layers=4, clip=shapely.box(-1, -1, 3, example.CORAL_DEPTH))
    assert np.all(band.contains(solid))  # branches 2.5 dx thick lie wholly in the 4 dx band
