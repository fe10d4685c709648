"""BIPICalculator (issue 7 item 3): E_BI, exact forces (FD in 2D and 3D, near corners), C, grad C, gamma;
bad input (item 10)."""
import math

import numpy as np
import pytest
from ase import Atoms
from ase.calculators.fd import calculate_numerical_forces

from ase_sphrelax import BIPICalculator
from ase_sphrelax.boundary import BoundarySegments, BoundaryTriangles, gamma_and_gradient
from ase_sphrelax.build import fill
from ase_sphrelax.domains import Circle, Polygon
from ase_sphrelax.kernels import get_kernel
from ase_sphrelax.models.bipi import BIPIModel, support_from_paper


def corner_polygon():
    """Convex and concave corners."""
    return Polygon([np.array([[0, 0], [1, 0], [1, 0.6], [0.5, 0.3], [0.2, 0.8], [0, 0.8]])])


def wedge(degrees=10.0):
    t = math.radians(degrees)
    return Polygon([np.array([[0.0, 0.0], [1.0, 0.0], [math.cos(t), math.sin(t)]])])


def fd_check(atoms, dim, eps=1e-6, n_atoms=None):
    """Forces against central differences of the energy (all particles, or the n nearest the boundary)."""
    f = atoms.get_forces()
    iatoms = None
    if n_atoms is not None:
        iatoms = np.argsort(atoms.calc.get_gamma(atoms))[:n_atoms].tolist()
    fn = np.array(calculate_numerical_forces(atoms, eps=eps, iatoms=iatoms, icarts=list(range(dim))))
    scale = np.abs(f).max()
    err = np.abs(f[iatoms if iatoms is not None else slice(None), :dim] - fn).max()
    assert err < 1e-6 * scale, (err, scale)
    if dim == 2:
        assert np.all(f[:, 2] == 0.0)


@pytest.mark.parametrize("make", [corner_polygon, wedge])
def test_forces_are_minus_gradient_2d(make):
    poly = make()
    dx = 0.05 if make is corner_polygon else 0.02
    atoms = fill(poly, dx, jitter=0.3, seed=1)
    # particles close to the corners too
    corners = np.concatenate(poly.loops)
    extra = corners + 0.2 * dx * (corners.mean(axis=0) - corners) / np.linalg.norm(
        corners.mean(axis=0) - corners, axis=1)[:, None]
    extra = extra[poly.contains(extra)]
    atoms.extend(Atoms(positions=np.column_stack([extra, np.zeros(len(extra))])))
    atoms.calc = BIPICalculator(h=4 * dx, dx=dx, boundary=poly)
    fd_check(atoms, 2)


@pytest.mark.parametrize("shape", ["box", "icosphere"])
def test_forces_are_minus_gradient_3d(shape):
    trimesh = pytest.importorskip("trimesh")
    mesh = trimesh.creation.box(extents=(1, 1, 1)) if shape == "box" else trimesh.creation.icosphere(2, 0.6)
    tri = BoundaryTriangles.from_trimesh(mesh)
    dx = 0.12
    atoms = fill(tri.domain, dx, jitter=0.3, seed=2)
    atoms.calc = BIPICalculator(h=3 * dx, dx=dx, boundary=tri)
    fd_check(atoms, 3, n_atoms=24)  # the 24 with the smallest gamma: at faces, edges and corners


def test_identities_against_brute_force():
    """C_a = V sum_b W_ab / gamma_a, grad C_a from brute-force sums, forces = -gamma grad C."""
    poly = corner_polygon()
    dx, h = 0.05, 0.2
    atoms = fill(poly, dx, jitter=0.2, seed=3)
    calc = BIPICalculator(h=h, dx=dx, boundary=poly)
    atoms.calc = calc
    r = atoms.positions
    k = get_kernel("wendland_c2", 2)
    d = r[:, None, :] - r[None, :, :]
    dist = np.linalg.norm(d, axis=2)
    w = k.w(dist, h)
    with np.errstate(invalid="ignore", divide="ignore"):
        dw = np.where(dist > 0, k.dw(dist, h) / dist, 0.0)[..., None] * d
    gamma, grad_gamma = gamma_and_gradient(r, BoundarySegments.from_domain(poly), h)
    v = dx**2
    c_ref = v * w.sum(axis=1) / gamma
    gc_ref = (v * dw.sum(axis=1) - grad_gamma) / gamma[:, None]
    np.testing.assert_allclose(calc.get_concentration(atoms), c_ref, rtol=1e-12)
    np.testing.assert_allclose(calc.get_concentration_gradient(atoms), gc_ref, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(calc.get_gamma(atoms), gamma, rtol=1e-14)
    f = atoms.get_forces()
    np.testing.assert_allclose(f, -gamma[:, None] * gc_ref, rtol=1e-10, atol=1e-10)
    e_ref = 0.5 * v * (w.sum() - len(r) * k.w0(h)) - gamma.sum()
    assert atoms.get_potential_energy() == pytest.approx(e_ref, rel=1e-12)
    assert calc.results["energies"].sum() == pytest.approx(e_ref, rel=1e-12)
    # a uniform interior has C ~ 1 and grad C ~ 0 far from the walls
    interior = poly.phi(r) < -h
    assert np.all(np.abs(calc.get_concentration(atoms)[interior] - 1) < 0.2)


def test_paper_convention():
    """BIPI2D's dx_r = 0.01, hsml = 0.02 (h_B / dx_r = 2) is support h = 4 dx; D = 0.5 h_B^2."""
    assert support_from_paper(2.0, 0.01) == pytest.approx(0.04)
    calc = BIPICalculator.from_paper(2.0, 0.01, corner_polygon())
    m = calc.model
    assert m.h == pytest.approx(0.04) and m.h_b == pytest.approx(0.02) and m.h_over_dx_paper == pytest.approx(2.0)
    assert m.diffusion == pytest.approx(0.5 * 0.02**2)
    assert m.cap == pytest.approx(0.005) and m.k_b == pytest.approx(0.006)
    # Eq. 15: the shift is capped at 0.5 dx, in the direction of Eq. 14
    g = np.array([[1e6, 0, 0], [1.0, 2.0, 0.0]])
    step = m.shift(g, np.zeros((2, 3)), np.ones(2))
    np.testing.assert_allclose(np.linalg.norm(step[0]), 0.005)
    np.testing.assert_allclose(step[1], -m.diffusion * g[1])
    # the step pressure term: p_s = 2 p_a subtracts half the near grad gamma over gamma
    step = m.shift(np.zeros((1, 3)), np.array([[0.0, 1.0, 0.0]]), np.array([0.5]))
    np.testing.assert_allclose(step, [[0.0, m.diffusion * 1.0, 0.0]])


def test_wall_gradient_rules():
    """The step pressure's band: 'ball' is the limit of 'centroid' on finely refined segments."""
    seg = BoundarySegments.from_vertices([[0, 0], [1, 0], [1, 1], [0, 1]])
    dx = 0.02
    atoms = Atoms(positions=[[0.5, 0.004, 0], [0.5, 0.009, 0], [0.5, 0.011, 0], [0.5, 0.5, 0], [0.003, 0.004, 0]])
    near = {}
    for rule, bnd in (("ball", seg), ("centroid", seg.refine(dx=dx, ratio=2000)), ("normal", seg)):
        calc = BIPICalculator(h=4 * dx, dx=dx, boundary=bnd, band_rule=rule)
        near[rule] = calc.get_property("wall_gradient", atoms)
    np.testing.assert_allclose(near["centroid"], near["ball"], atol=2e-3 * np.abs(near["ball"]).max())
    assert np.all(near["ball"][2:4] == 0) and near["ball"][0, 1] > near["ball"][1, 1] > 0
    # 'normal' takes the whole wall within h as soon as the particle is within 0.5 dx of its line
    gamma, grad = gamma_and_gradient(atoms.positions[:2], seg, 4 * dx)
    np.testing.assert_allclose(near["normal"][:2], grad, rtol=1e-12)


def test_bad_input():
    poly = corner_polygon()
    with pytest.raises(ValueError, match="h must be at least dx"):
        BIPICalculator(h=0.01, dx=0.02, boundary=poly)
    with pytest.raises(ValueError, match="to_polygon"):
        BIPICalculator(h=0.1, dx=0.02, boundary=Circle((0, 0), 1))
    with pytest.raises(ValueError, match="boundary must be given"):
        BIPICalculator(h=0.1, dx=0.02)
    with pytest.raises(ValueError, match="dim=3 but the boundary is 2D"):
        BIPICalculator(h=0.1, dx=0.02, boundary=poly, dim=3)
    with pytest.raises(ValueError, match="band_rule"):
        BIPICalculator(h=0.1, dx=0.02, boundary=poly, band_rule="wide")
    with pytest.raises(TypeError, match="unknown parameter"):
        BIPICalculator(h=0.1, dx=0.02, boundary=poly, hsml=0.02)
    with pytest.raises(ValueError, match="h must be"):
        BIPICalculator(h=-1, dx=0.02, boundary=poly)
    with pytest.raises(ValueError, match="h_over_dx_paper"):
        BIPICalculator.from_paper(0, 0.02, poly)
    calc = BIPICalculator(h=0.1, dx=0.025, boundary=poly)
    atoms = fill(poly, 0.025, seed=0)
    atoms.positions[0, 2] = 0.1
    atoms.calc = calc
    with pytest.raises(ValueError, match="z = 0"):
        atoms.get_potential_energy()
    atoms.positions[0, 2] = 0.0
    atoms.pbc = (True, True, False)
    with pytest.raises(ValueError, match="pbc"):
        atoms.get_potential_energy()
    atoms.pbc = False
    atoms.positions[0] = [5.0, 5.0, 0.0]  # far outside: gamma = 0, C undefined, energy and forces defined
    assert np.isfinite(atoms.get_potential_energy()) and np.all(np.isfinite(atoms.get_forces()))
    with pytest.raises(ValueError, match=r"particles \[0\].*gamma = 0"):
        calc.get_concentration(atoms)
    with pytest.raises(ValueError, match="dim must be 2 or 3"):
        BIPIModel(0.1, 0.02, dim=1)


def test_coincident_particles_and_set():
    poly = corner_polygon()
    dx = 0.05
    atoms = fill(poly, dx, seed=0)
    atoms.positions[1] = atoms.positions[0]
    calc = BIPICalculator(h=4 * dx, dx=dx, boundary=poly)
    atoms.calc = calc
    f = atoms.get_forces()
    assert np.all(np.isfinite(f)) and np.all(np.isfinite(calc.get_concentration(atoms)))
    e = atoms.get_potential_energy()
    calc.set(h=3 * dx)
    fresh = BIPICalculator(h=3 * dx, dx=dx, boundary=poly)
    assert atoms.get_potential_energy() == pytest.approx(fresh.get_potential_energy(atoms), rel=1e-12) != e


def test_merged_collinear_segments_give_the_same_results():
    """The calculator integrates over the polygon's segments (collinear runs merged): same values."""
    from ase_sphrelax.boundary import BoundaryIntegrals
    from ase_sphrelax.neighbors import NeighborList

    seg = BoundarySegments.from_vertices([[0, 0], [1, 0], [1, 1], [0, 1]]).refine(max_length=0.01)
    dx = 0.05
    calc = BIPICalculator(h=4 * dx, dx=dx, boundary=seg)
    assert len(calc.integrals.boundary) == 4 and len(seg) == 400
    atoms = fill(seg.domain, dx, jitter=0.3, seed=5)
    calc.calculate(atoms, ["forces", "wall_gradient"])
    fine = BoundaryIntegrals(seg, 4 * dx)
    nlist = NeighborList(4 * dx)
    nlist.update(atoms.positions, np.zeros((3, 3)), False, store=False)
    ref = fine.compute(nlist, atoms.positions, band=calc.model.band)
    np.testing.assert_allclose(calc.results["gamma"], ref.gamma_p, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(calc.results["grad_gamma"], ref.grad_gamma_pc, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(calc.results["wall_gradient"], ref.near_pc, rtol=1e-10, atol=1e-10)
