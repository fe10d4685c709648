"""BIPI with periodic directions (issue 17 item 2): gamma and its gradient against a long bounded
channel, exact forces by central differences with periodic cells, a packed periodic channel with a
cylinder, the dropped face edges, the command line."""
import json
import subprocess
import sys
import warnings

import numpy as np
import pytest
from ase import Atoms
from ase.calculators.fd import calculate_numerical_forces
from ase.io import read
from hypothesis import given, settings
from hypothesis import strategies as st

from ase_sphrelax.boundary import BoundarySegments, BoundaryTriangles, gamma_and_gradient
from ase_sphrelax.boundary.periodic import PeriodicFacesWarning
from ase_sphrelax.calculators.bipi import BIPICalculator
from ase_sphrelax.cli import main
from ase_sphrelax.domains import Polygon

L, W, H_SUPPORT = 1.0, 0.6, 0.3  # period, channel width, kernel support
CENTRE, RADIUS = np.array([0.2, 0.3]), 0.15  # the cylinder's support reaches across the seam x = 0
N_LONG = 7  # periods of the long bounded channel; the periodic cell is compared with its middle period


def cylinder(centre, radius=RADIUS, n=36):
    """A clockwise loop (a hole) around ``centre``."""
    angle = -2 * np.pi * np.arange(n) / n
    return np.asarray(centre) + radius * np.c_[np.cos(angle), np.sin(angle)]


def channel_polygon(x0=0.0, periods=1, centre=CENTRE):
    """A channel [x0, x0 + periods L] x [0, W] drawn closed, with a cylinder in every period."""
    outer = np.array([[x0, 0.0], [x0 + periods * L, 0.0], [x0 + periods * L, W], [x0, W]])
    return Polygon([outer] + [cylinder(np.asarray(centre) + [k * L, 0.0]) for k in range(periods)])


def periodic_channel(x0=0.0, centre=CENTRE):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PeriodicFacesWarning)
        return BoundarySegments.from_polygon(channel_polygon(x0, centre=centre), pbc=[True, False])


PERIODIC = periodic_channel()
LONG = BoundarySegments.from_polygon(channel_polygon(periods=N_LONG))
MIDDLE = np.array([(N_LONG // 2) * L, 0.0, 0.0])


def as_points(xy):
    r = np.zeros((len(xy), 3))
    r[:, :2] = xy
    return r


# -- gamma -----------------------------------------------------------------------------------
coordinate_x = st.one_of(st.floats(0.0, L), st.sampled_from([0.0, L, 0.5 * L, np.nextafter(L, 0.0)]))
coordinate_y = st.one_of(st.floats(-0.2, W + 0.2), st.sampled_from([0.0, W, 0.5 * W, 1e-300, -1e-12]))


@settings(max_examples=60, deadline=None, database=None)
@given(st.lists(st.tuples(coordinate_x, coordinate_y), min_size=1, max_size=20))
def test_gamma_equals_long_channel(xy):
    """gamma and grad gamma of the periodic channel = those of a 7-period bounded channel in its middle
    period, at points anywhere in the cell, on the periodic faces (x = 0, x = L) and on the walls."""
    r = as_points(np.array(xy))
    g_p, grad_p = gamma_and_gradient(r, PERIODIC, H_SUPPORT)
    g_l, grad_l = gamma_and_gradient(r + MIDDLE, LONG, H_SUPPORT)
    assert np.max(np.abs(g_p - g_l)) <= 1e-12
    assert np.max(np.abs(grad_p - grad_l)) <= 1e-12


def test_gamma_of_images_and_of_a_shifted_drawing():
    """A point and its images (any number of periods away) have the same gamma; a channel drawn from
    x0 = -0.35 (walls crossing the cell face, split there) is the same periodic domain."""
    rng = np.random.default_rng(3)
    r = as_points(rng.uniform([0, -0.1], [L, W + 0.1], (400, 2)))
    g, grad = gamma_and_gradient(r, PERIODIC, H_SUPPORT)
    for k in (-3, 1, 5):
        g_k, grad_k = gamma_and_gradient(r + [k * L, 0, 0], PERIODIC, H_SUPPORT)
        assert np.max(np.abs(g_k - g)) <= 1e-12 and np.max(np.abs(grad_k - grad)) <= 1e-12
    shifted = periodic_channel(x0=-0.35)
    assert len(shifted) == len(PERIODIC)  # the walls split at x = 0 are merged again across the seams
    assert shifted.surface == pytest.approx(PERIODIC.surface, rel=1e-14)
    g_s, grad_s = gamma_and_gradient(r, shifted, H_SUPPORT)
    assert np.max(np.abs(g_s - g)) <= 1e-12 and np.max(np.abs(grad_s - grad)) <= 1e-12
    assert np.array_equal(shifted.contains(r), PERIODIC.contains(r))


def joined_boxes(periods, extents=(L, 0.8, 0.6)):
    """A box channel of ``periods`` copies of the cell's box mesh along x, the inner faces removed (the same
    triangles as the periodic cell's)."""
    trimesh = pytest.importorskip("trimesh")
    box = trimesh.creation.box(extents=extents)
    box.apply_translation(0.5 * np.asarray(extents))
    v_tkc = box.triangles
    lo_face = np.all(np.abs(v_tkc[:, :, 0]) < 1e-12, axis=1)
    hi_face = np.all(np.abs(v_tkc[:, :, 0] - L) < 1e-12, axis=1)
    vertices, faces = [], []
    for k in range(periods):
        keep = ~((lo_face & (k > 0)) | (hi_face & (k < periods - 1)))
        vertices.append(box.vertices + [k * L, 0, 0])
        faces.append(box.faces[keep] + k * len(box.vertices))
    mesh = trimesh.Trimesh(np.concatenate(vertices), np.concatenate(faces), process=False)
    mesh.merge_vertices()
    return box, mesh


def test_gamma_3d_periodic_box_equals_long_box():
    box, long_mesh = joined_boxes(5)
    with pytest.warns(PeriodicFacesWarning, match="4 triangles on the periodic faces"):
        periodic = BoundaryTriangles.from_trimesh(box).with_cell([True, False, False])
    long = BoundaryTriangles.from_trimesh(long_mesh)
    rng = np.random.default_rng(0)
    r = rng.uniform([0, -0.1, -0.1], [L, 0.9, 0.7], (40, 3))
    r[:8, 0] = 0.0
    r[8:12, 1] = 0.0  # on the wall y = 0
    g_p, grad_p = gamma_and_gradient(r, periodic, H_SUPPORT)
    g_l, grad_l = gamma_and_gradient(r + [2 * L, 0, 0], long, H_SUPPORT)
    assert np.max(np.abs(g_p - g_l)) <= 1e-12
    assert np.max(np.abs(grad_p - grad_l)) <= 1e-12
    assert np.array_equal(periodic.contains(r), long.contains(r + [2 * L, 0, 0]))


# -- forces ----------------------------------------------------------------------------------
def random_inside(boundary, n, lo, hi, seed, margin=0.02):
    rng = np.random.default_rng(seed)
    r = rng.uniform(lo, hi, (20 * n, len(lo)))
    r = r[boundary.domain.phi(r) < -margin][:n]
    assert len(r) == n
    return r


def test_forces_are_exact_2d_periodic():
    dx = 0.08
    r = random_inside(PERIODIC, 40, [0, 0], [L, W], seed=1)
    r[:4, 0] = [0.01, 0.03, L - 0.01, L - 0.04]  # across the seam
    atoms = Atoms(positions=as_points(r), cell=[L, 1.0, 1.0], pbc=[True, False, False])
    atoms.calc = BIPICalculator(h=H_SUPPORT, dx=dx, boundary=PERIODIC)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        f = atoms.get_forces()
        f_fd = calculate_numerical_forces(atoms, eps=1e-6, icarts=[0, 1])
    assert np.max(np.abs(f[:, :2] - f_fd)) < 1e-8 * max(1.0, np.max(np.abs(f)))
    # the periodic energy differs from the bounded one of the same particles (images are seen)
    bounded = BIPICalculator(h=H_SUPPORT, dx=dx, boundary=PERIODIC.polygon)
    e_periodic = atoms.get_potential_energy()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        e_bounded = bounded.get_potential_energy(Atoms(positions=atoms.positions, pbc=False))
    assert abs(e_periodic - e_bounded) > 1e-3


def test_forces_are_exact_3d_periodic_box():
    box, _ = joined_boxes(1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PeriodicFacesWarning)
        boundary = BoundaryTriangles.from_trimesh(box).with_cell([True, True, False])
    r = random_inside(boundary, 14, [0, 0, 0], [L, 0.8, 0.6], seed=2, margin=0.03)
    r[:2, 0] = [0.02, L - 0.02]
    r[2:4, 1] = [0.01, 0.8 - 0.03]
    atoms = Atoms(positions=r, cell=[L, 0.8, 1.0], pbc=[True, True, False])
    atoms.calc = BIPICalculator(h=H_SUPPORT, dx=0.1, boundary=boundary)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        f = atoms.get_forces()
        f_fd = calculate_numerical_forces(atoms, eps=1e-6)
    assert np.max(np.abs(f - f_fd)) < 1e-7 * max(1.0, np.max(np.abs(f)))


def test_calculator_refuses_mismatched_cells():
    calc = BIPICalculator(h=H_SUPPORT, dx=0.1, boundary=PERIODIC)
    atoms = Atoms(positions=[[0.5, 0.05, 0.0], [0.5, 0.5, 0]], cell=[L, 1, 1], pbc=False)
    atoms.calc = calc
    with pytest.raises(ValueError, match=r"atoms.pbc must be \[True, False\]"):
        atoms.get_potential_energy()
    atoms.pbc = [True, False, False]
    atoms.cell = [2 * L, 1, 1]
    with pytest.raises(ValueError, match=r"atoms.cell\[0\] must be the boundary's period"):
        atoms.get_potential_energy()
    bounded = BIPICalculator(h=H_SUPPORT, dx=0.1, boundary=PERIODIC.polygon)
    atoms.calc = bounded
    with pytest.raises(ValueError, match="bounded BIPI domain.*with_cell"):
        atoms.get_potential_energy()


@pytest.mark.parametrize("pbc,cell,message", [
    ([True, False, True], None, "periodic along its 2 axes"),
    ("x", None, "pbc must be a bool"),
    ([True, False], [0.5, 0], "more than the period"),
    ([True, False], [[1, 0.2, 0], [0, 1, 0], [0, 0, 1]], "must lie along x"),
    ([True, False], [-1.0, 0.0], "finite and >= 0"),
])
def test_with_cell_bad_input(pbc, cell, message):
    with pytest.raises(ValueError, match=message):
        BoundarySegments.from_polygon(channel_polygon()).with_cell(pbc, cell)


def test_support_beyond_the_images_is_refused():
    with pytest.raises(ValueError, match="exceeds the periodic images' reach"):
        gamma_and_gradient([[0.5, 0.3, 0.0]], PERIODIC, 1.5 * L)
    wide = PERIODIC.with_cell([True, False], reach=2, quiet=True)
    g, _ = gamma_and_gradient([[0.5, 0.3, 0.0]], wide, 1.5 * L)
    g_long, _ = gamma_and_gradient(np.array([[0.5, 0.3, 0.0]]) + MIDDLE, LONG, 1.5 * L)
    assert abs(g[0] - g_long[0]) <= 1e-12


def test_wall_without_continuation_is_refused():
    # a step in the floor: the wall ends at y = 0 on the left face but at y = 0.1 on the right one
    steps = Polygon([np.array([[0, 0], [0.5, 0], [0.5, 0.1], [L, 0.1], [L, W], [0, W]])])
    with pytest.raises(ValueError, match="does not continue at the opposite face"):
        BoundarySegments.from_polygon(steps, pbc=[True, False])


# -- dropped face edges ----------------------------------------------------------------------
def write_channel(path, centre=(0.5, 0.25), radius=0.1, n=32, length=L, width=0.5):
    lines = [f"0 0 {length} 0", f"{length} 0 {length} {width}", f"{length} {width} 0 {width}", f"0 {width} 0 0"]
    loop = cylinder(centre, radius, n)
    for a, b in zip(loop, np.roll(loop, -1, axis=0)):
        lines.append(f"{a[0]:.17g} {a[1]:.17g} {b[0]:.17g} {b[1]:.17g}")
    path.write_text("\n".join(lines) + "\n")
    return path


def test_edge_file_face_edges_dropped_with_a_message(tmp_path):
    path = write_channel(tmp_path / "channel.edges")
    with pytest.warns(PeriodicFacesWarning, match=r"2 segments on the periodic faces \(x\) dropped") as record:
        boundary = BoundarySegments.from_edges(path, pbc=[True, False])
    assert len(record) == 1 and len(str(record[0].message).splitlines()) == 1
    assert boundary.periodic.label == "x"
    cylinder_length = 32 * 2 * 0.1 * np.sin(np.pi / 32)
    assert boundary.surface == pytest.approx(2 * L + cylinder_length, rel=1e-12)  # the face edges are gone
    with pytest.warns(PeriodicFacesWarning, match=r"4 segments on the periodic faces \(x y\)"):
        both = BoundarySegments.from_edges(path, pbc=True)
    assert both.surface == pytest.approx(cylinder_length, rel=1e-12)  # only the cylinder is left
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a body shorter than the period has no face edges to drop
        body = BoundarySegments.from_edges(path, pbc=[True, False], cell=[1.5, 0])
    assert body.surface == pytest.approx(2 * L + 2 * 0.5 + cylinder_length, rel=1e-12)


# -- packing ---------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def packed_channel():
    from ase_sphrelax.drivers.bipi_packer import pack

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        boundary = BoundarySegments.from_polygon(
            Polygon([np.array([[0, 0], [L, 0], [L, 0.5], [0, 0.5]]), cylinder((0.5, 0.25), 0.1, 48)]),
            pbc=[True, False])
        atoms, packer, start = pack(boundary, 0.05, max_steps_2a=150, max_steps_2c=100)
    return boundary, atoms, packer, start


def nearest_distances(atoms):
    from ase.neighborlist import neighbor_list

    i, d = neighbor_list("id", atoms, 0.2)
    out = np.full(len(atoms), np.inf)
    np.minimum.at(out, i, d)
    return out


def test_packed_periodic_channel(packed_channel):
    boundary, atoms, packer, start = packed_channel
    dx = 0.05
    assert len(atoms) == len(start)
    assert list(atoms.pbc) == [True, False, False] and np.allclose(atoms.cell[0], [L, 0, 0])
    x = atoms.positions[:, 0]
    assert np.all((x >= 0) & (x < L))  # wrapped into the cell
    assert boundary.contains(atoms.positions).all()  # no particle outside
    # spacing across the seam as in the bulk: nearest neighbours by minimum image
    near_seam = (x < dx) | (x > L - dx)
    bulk = (np.abs(x - 0.5 * L) > 0.25) & ~near_seam
    d = nearest_distances(atoms)
    assert near_seam.sum() >= 10 and np.all(d > 0.7 * dx)
    assert abs(np.median(d[near_seam]) - np.median(d[bulk])) < 0.05 * dx
    # particles on both sides of the seam see each other: the packing moved particles across or along it
    # consistently with a shifted cell (the energy is invariant under a shift of particles and boundary)
    e = atoms.calc.get_potential_energy(atoms)
    shift = 0.37 * L
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        moved_boundary = BoundarySegments.from_polygon(
            Polygon([np.array([[shift, 0], [shift + L, 0], [shift + L, 0.5], [shift, 0.5]]),
                     cylinder((0.5 + shift, 0.25), 0.1, 48)]), pbc=[True, False])
        moved = Atoms(positions=atoms.positions + [shift, 0, 0], cell=atoms.cell, pbc=atoms.pbc)
        moved.wrap()
        moved.calc = BIPICalculator(h=4 * dx, dx=dx, boundary=moved_boundary)
        assert moved.get_potential_energy() == pytest.approx(e, rel=1e-10, abs=1e-12)


def test_packing_improves_the_start(packed_channel):
    _, atoms, packer, _ = packed_channel
    s = packer.summary()
    assert s["gradc_avg_2c_last"] < s["gradc_avg_2a_first"]


# -- command line ----------------------------------------------------------------------------
def sphrelax(*args):
    return subprocess.run([sys.executable, "-m", "ase_sphrelax.cli", *args], capture_output=True, text=True,
                          timeout=600)


def test_cli_pack_periodic(tmp_path, capsys):
    path = write_channel(tmp_path / "channel.edges")
    out = tmp_path / "out"
    code = main(["pack", "--method", "bipi", "--boundary", str(path), "--dx", "0.05", "--h", "4", "--periodic", "x",
                 "--out", str(out), "--max-steps-2a", "20", "--max-steps-2c", "10"])
    assert code == 0
    text = capsys.readouterr().out
    assert "2 segments on the periodic faces (x) dropped" in text
    atoms = read(out / "packed.extxyz")
    assert list(atoms.pbc) == [True, False, False] and np.allclose(atoms.cell[0], [L, 0, 0])
    assert np.all((atoms.positions[:, 0] >= 0) & (atoms.positions[:, 0] < L))
    data = json.loads((out / "summary.json").read_text())
    assert data["summary"]["periodic"] == [True, False] and data["summary"]["n_outside"] == 0


def test_cli_cell_gives_the_period(tmp_path, capsys):
    path = write_channel(tmp_path / "channel.edges")
    out = tmp_path / "out"
    # a closed body (a channel segment with its end walls) repeated every 1.2: no face edge is dropped
    assert main(["pack", "--boundary", str(path), "--dx", "0.05", "--periodic", "x", "--cell", "1.2", "0",
                 "--out", str(out), "--max-steps-2a", "5", "--max-steps-2c", "5"]) == 0
    assert "dropped" not in capsys.readouterr().out
    atoms = read(out / "packed.extxyz")
    assert np.allclose(atoms.cell[0], [1.2, 0, 0]) and list(atoms.pbc) == [True, False, False]
    assert np.all(atoms.positions[:, 0] < L)


@pytest.mark.parametrize("args,message", [
    (["--periodic", "w"], "--periodic: 'w' is not an axis of the 2D boundary; accepted: x, y, or x y in 2D"),
    (["--periodic", "z"], "--periodic: 'z' is not an axis"),
    (["--periodic", "x", "x"], "--periodic: axis x given twice"),
    (["--cell", "2", "1"], "--cell needs --periodic"),
    (["--periodic", "x", "--cell", "2"], "--cell: give 2 finite lengths"),
    (["--periodic", "x", "--cell", "0.5", "0"], "--periodic/--cell:"),
])
def test_cli_bad_periodic_values(tmp_path, args, message):
    path = write_channel(tmp_path / "channel.edges")
    result = sphrelax("pack", "--boundary", str(path), "--dx", "0.05", "--out", str(tmp_path / "o"), *args)
    assert result.returncode == 2
    assert message in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1 and "Traceback" not in result.stderr
