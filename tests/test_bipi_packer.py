"""BIPIPacker (issue 7 items 4, 8, 10): the paper's stages, no escape, the boundary layer at half a spacing,
|grad C| drop in Step 2c, FixAtoms, stopping rules, histories; hard cases (10-degree wedge, thin trailing
edge, a hole smaller than 2h, 3D)."""
import json
import math

import numpy as np
import pytest
from ase.constraints import FixAtoms

from ase_sphrelax import BIPICalculator, BIPIPacker
from ase_sphrelax.boundary import BoundarySegments, BoundaryTriangles
from ase_sphrelax.drivers.bipi_packer import initial_fill
from ase_sphrelax.plotting import plot_packing_history as plot_history


def pack(boundary, dx, ratio=2.0, **kwargs):
    atoms = initial_fill(boundary, dx)
    calc = BIPICalculator.from_paper(ratio, dx, boundary)
    opt = BIPIPacker(atoms, calc, **kwargs)
    opt.run()
    return atoms, opt


def layer_distance(boundary, atoms, dx):
    """Distances (units of dx) of the boundary layer (within 0.75 dx) and of all particles."""
    d = -boundary.domain.phi(atoms.positions) / dx
    return d[d < 0.75], d


@pytest.fixture(scope="module")
def trapezoid():
    from conftest import GEOMETRIES

    if not GEOMETRIES.is_dir():
        pytest.skip("../shared/geometries is not beside the checkout")
    seg = BoundarySegments.from_edges(GEOMETRIES / "TrapezoidalTank.edges")
    start = initial_fill(seg, 0.04)
    atoms, opt = pack(seg, 0.04)
    return seg, start, atoms, opt


def test_initial_fill_is_bipi2d_step1(geometries):
    seg = BoundarySegments.from_edges(geometries / "TrapezoidalTank.edges")
    atoms = initial_fill(seg, 0.04)
    r = atoms.positions[:, :2]
    q = r / 0.04 - 0.5
    np.testing.assert_allclose(q, np.round(q), atol=1e-9)  # cell centres, no jitter
    assert np.all(-seg.domain.phi(atoms.positions) >= 0.04 / 8)
    assert np.all(atoms.positions[:, 2] == 0) and not atoms.pbc.any()
    with pytest.raises(ValueError, match="larger than the shape"):
        initial_fill(seg, 2.0)


def test_trapezoid_stays_inside_and_layer_at_half_spacing(trapezoid):
    seg, start, atoms, opt = trapezoid
    dx = 0.04
    assert len(atoms) == len(start)
    layer, d = layer_distance(seg, atoms, dx)
    assert np.all(d > 0)  # no particle outside
    assert abs(layer.mean() - 0.5) < 0.05, layer.mean()  # within 10 % of 0.5 dx
    s = opt.summary()
    assert opt.stage == "done" and s["iterations_2a"] > 0 and s["iterations_2c"] > 0
    # |grad C|_avg of the unfrozen particles drops by two orders of magnitude in Step 2c
    assert opt.final_gradc_avg() < 1e-2 * s["gradc_avg_2c_first"], (s, opt.final_gradc_avg())


def test_step_2b_freezes_through_gamma_and_2c_keeps_them(trapezoid):
    seg, start, atoms, opt = trapezoid
    fix = [c for c in atoms.constraints if isinstance(c, FixAtoms)]
    assert len(fix) == 1 and np.array_equal(np.sort(fix[0].index), np.sort(opt.frozen))
    assert 0.6 < opt.gamma_wall < 0.8
    # the frozen ones are the boundary layer (within about k_b = 0.6 dx)
    _, d = layer_distance(seg, atoms, 0.04)
    assert np.all(d[opt.frozen] < 0.75)
    rows_2c = [r for r in opt.history if r["stage"] == "2c"]
    assert all(r["n_pack"] == len(atoms) - len(opt.frozen) for r in rows_2c)


def test_step_2a_works_on_the_selected_particles_only(trapezoid):
    seg, start, atoms, opt = trapezoid
    rows = [r for r in opt.history if r["stage"] == "2a"]
    n_sel = rows[0]["n_selected"]
    assert rows[0]["n_pack"] < n_sel < len(atoms)
    # packable: within k_a = h of the boundary; selected adds their neighbours within h
    d = -seg.domain.phi(start.positions)
    h = opt.model.h
    assert rows[0]["n_pack"] == np.sum(d < h)
    assert n_sel <= np.sum(d < 2 * h + 1e-12)


def test_history_saved_and_plotted(trapezoid, tmp_path):
    _, _, _, opt = trapezoid
    opt.save(tmp_path / "history.json")
    data = json.loads((tmp_path / "history.json").read_text())
    assert {"parameters", "summary", "history"} <= set(data)
    row = data["history"][0]
    assert {"stage", "iteration", "tpd_avg", "gradc_avg", "n_pack", "time", "rejected"} <= set(row)
    assert data["parameters"]["h_over_dx_paper"] == pytest.approx(2.0)
    plot_history(opt.history, tmp_path / "history.png", title="trapezoid")
    assert (tmp_path / "history.png").stat().st_size > 1000


def test_stopping_rule_definition():
    """Stop after iteration i >= w when |X_i - X_(i-w)| <= tol |X_(i-w)|, X_(i-w) > 0."""
    opt = BIPIPacker.__new__(BIPIPacker)
    opt.window, opt.tol = 3, 0.01
    assert not opt._stop([0.0, 1.0, 2.0])  # i < w
    assert not opt._stop([0.0, 1.0, 1.0, 1.0])  # X_(i-w) = 0
    assert opt._stop([0.0, 1.0, 1.0, 1.0, 1.005])
    assert not opt._stop([0.0, 1.0, 1.0, 1.0, 1.02])


def test_user_fixatoms_respected_and_outside_particles(geometries):
    seg = BoundarySegments.from_edges(geometries / "TrapezoidalTank.edges")
    dx = 0.05
    atoms = initial_fill(seg, dx)
    fixed = [0, 5, 17]
    atoms.set_constraint(FixAtoms(indices=fixed))
    before = atoms.positions[fixed].copy()
    BIPIPacker(atoms, BIPICalculator.from_paper(2.0, dx, seg), max_steps_2a=30, max_steps_2c=30).run()
    np.testing.assert_array_equal(atoms.positions[fixed], before)
    # outside particles: refused by default, moved in on request
    atoms = initial_fill(seg, dx)
    atoms.positions[3] = [-0.1, 0.5, 0.0]
    atoms.positions[4] = [0.5, 0.0, 0.0]  # on the boundary
    calc = BIPICalculator.from_paper(2.0, dx, seg)
    with pytest.raises(ValueError, match=r"particles \[3, 4\].*outside"):
        BIPIPacker(atoms, calc)
    opt = BIPIPacker(atoms, calc, outside="move", max_steps_2a=5, max_steps_2c=5)
    assert sorted(opt.moved_in.tolist()) == [3, 4]
    np.testing.assert_allclose(-seg.domain.phi(atoms.positions[[3, 4]]), 0.5 * dx)
    opt.run()
    assert np.all(seg.domain.phi(atoms.positions) < 0)


def test_bad_packer_input(geometries):
    seg = BoundarySegments.from_edges(geometries / "TrapezoidalTank.edges")
    atoms = initial_fill(seg, 0.1)
    calc = BIPICalculator.from_paper(2.0, 0.1, seg)
    with pytest.raises(TypeError, match="BIPICalculator"):
        BIPIPacker(atoms, object())
    with pytest.raises(ValueError, match="stages"):
        BIPIPacker(atoms, calc, stages=("2c", "2a"))
    with pytest.raises(ValueError, match="window"):
        BIPIPacker(atoms, calc, window=0)
    with pytest.raises(ValueError, match="outside"):
        BIPIPacker(atoms, calc, outside="drop")
    with pytest.raises(ValueError, match="tol"):
        BIPIPacker(atoms, calc, tol=-1)


# ---------------------------------------------------------------- hard cases
def test_ten_degree_wedge_no_escape():
    t = math.radians(10.0)
    seg = BoundarySegments.from_vertices([[0, 0], [1, 0], [math.cos(t), math.sin(t)]])
    atoms, opt = pack(seg, 0.01, max_steps_2a=150, max_steps_2c=150)
    _, d = layer_distance(seg, atoms, 0.01)
    assert np.all(d > 0) and len(atoms) == len(initial_fill(seg, 0.01))


def test_thin_trailing_edge_no_escape(geometries):
    """The airfoil's trailing edge (0.05 thick) is thinner than dx = 0.1."""
    seg = BoundarySegments.from_edges(geometries / "AirFoilSolid.edges")
    dx = 0.1
    atoms, opt = pack(seg, dx, max_steps_2a=100, max_steps_2c=100)
    layer, d = layer_distance(seg, atoms, dx)
    assert np.all(d > 0)
    assert abs(layer.mean() - 0.5) < 0.1


def test_hole_smaller_than_2h():
    """A square hole of side 0.06 < 2 h = 0.16: no particle enters it."""
    hole = [[0.5, 0.5], [0.56, 0.5], [0.56, 0.56], [0.5, 0.56]]
    seg = BoundarySegments.from_vertices([[0, 0], [1, 0], [1, 1], [0, 1]], holes=[hole])
    atoms, opt = pack(seg, 0.02, max_steps_2a=100, max_steps_2c=100)
    r = atoms.positions
    inside_hole = (r[:, 0] > 0.5) & (r[:, 0] < 0.56) & (r[:, 1] > 0.5) & (r[:, 1] < 0.56)
    assert not inside_hole.any()
    _, d = layer_distance(seg, atoms, 0.02)
    assert np.all(d > 0)


def test_complex_shape_bunny(geometries):
    seg = BoundarySegments.from_edges(geometries / "Standford2DBunny.edges")
    dx = 2.5
    atoms, opt = pack(seg, dx, max_steps_2a=200, max_steps_2c=200)
    layer, d = layer_distance(seg, atoms, dx)
    assert np.all(d > 0)
    assert abs(layer.mean() - 0.5) < 0.05


@pytest.mark.slow
def test_3d_cube_and_icosphere():
    trimesh = pytest.importorskip("trimesh")
    for mesh, dx in ((trimesh.creation.box(extents=(1, 1, 1)), 0.125), (trimesh.creation.icosphere(3, 0.5), 0.1)):
        tri = BoundaryTriangles.from_trimesh(mesh)
        atoms, opt = pack(tri, dx, max_steps_2a=40, max_steps_2c=40)
        layer, d = layer_distance(tri, atoms, dx)
        assert np.all(d > 0)
        assert abs(layer.mean() - 0.5) < 0.1
        assert len(opt.frozen) > 0
