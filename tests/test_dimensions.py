"""Issue 10 item 1: one dimension rule (ase_sphrelax.checks.resolve_dim) everywhere, no silent projection."""
import numpy as np
import pytest
from ase import Atoms

from ase_sphrelax import FanCalculator
from ase_sphrelax.analysis import quality_summary
from ase_sphrelax.build import fill, periodic_box
from ase_sphrelax.checks import resolve_dim
from ase_sphrelax.domains import Box, Circle, Sphere


def _no_info(atoms):
    atoms.info.pop("dim", None)
    return atoms


def test_inference_rule():
    assert resolve_dim(_no_info(periodic_box(4, dim=3, jitter=0.2, seed=0))) == 3  # periodic in z
    assert resolve_dim(_no_info(periodic_box(4, dim=2, jitter=0.2, seed=0))) == 2  # z = 0, not periodic in z
    assert resolve_dim(_no_info(fill(Sphere((0, 0, 0), 0.3), 0.1))) == 3  # z varies
    line = Atoms("X3", positions=[(0, 0, 0), (1, 0, 0), (2, 0, 0)], cell=[3, 0, 0], pbc=(True, False, False))
    assert resolve_dim(line) == 1
    flat = Atoms("X2", positions=[(0, 0, 0.5), (1, 0, 0.5)])
    with pytest.raises(ValueError, match=r"every particle has z = 0.5 .*ambiguous.*positions\[:, 2\] = 0.*dim=3"):
        resolve_dim(flat)
    assert resolve_dim(flat, 3) == 3  # a flat 3D set off z = 0 is fine when asked for


def test_mismatches_are_errors_that_name_the_remedy():
    a3, a2 = _no_info(periodic_box(4, dim=3)), _no_info(periodic_box(4, dim=2))
    with pytest.raises(ValueError, match=r"2D system cannot be periodic along z.*dim=3"):
        resolve_dim(a3, 2)
    with pytest.raises(ValueError, match=r"dim=3 but every particle lies at z = 0.*pass dim=2 or dim=None"):
        resolve_dim(a2, 3)
    a2.positions[1, 2] = 1e-3
    with pytest.raises(ValueError, match=r"2D system needs every particle at z = 0, but 1 have z != 0 .*particle 1"):
        resolve_dim(a2, 2)
    with pytest.raises(ValueError, match=r"domain is 2D but dim=3: pass dim=2 or dim=None"):
        resolve_dim(a2, 3, Circle((0, 0), 1.0))
    with pytest.raises(ValueError, match=r"atoms.info\['dim'\] = 2 .* but dim=3"):
        resolve_dim(periodic_box(4, dim=2), 3)


def test_builders_declare_their_dimension():
    """build.fill / periodic_box follow the rule and say so in info['dim']; a flat 3D layer stays 3D."""
    for atoms, dim in ((fill(Circle((0, 0), 0.5), 0.1), 2), (fill(Sphere((0, 0, 0), 0.3), 0.1), 3),
                       (periodic_box(4, dim=2), 2), (periodic_box(3, dim=3), 3)):
        assert atoms.info["dim"] == dim and resolve_dim(atoms) == dim
    layer = fill(Box((0, 0, 0), (1, 1, 0.1)), 0.1, jitter=0.0)  # one layer of cells: every z = 0.05
    assert np.ptp(layer.positions[:, 2]) == 0 and resolve_dim(layer) == 3


def test_fill_refuses_a_2d_origin_off_the_plane():
    with pytest.raises(ValueError, match="origin: a 2D mesh lies at z = 0"):
        fill(Circle((0, 0), 0.5), 0.1, origin=(0.0, 0.0, 0.3))
    assert len(fill(Circle((0, 0), 0.5), 0.1, origin=(0.0, 0.0, 0.0))) == len(fill(Circle((0, 0), 0.5), 0.1))


def test_fan_calculator_infers_the_dimension():
    """3D periodic atoms with the default: E as with dim=3 (was 4070 with F_z = 0); 2D as with dim=2."""
    a3 = periodic_box(6, dx=1.0, dim=3, jitter=0.2, seed=1)
    e3 = FanCalculator(h=2.6, dx=1.0, dim=3).get_potential_energy(a3)
    a3.calc = FanCalculator(h=2.6, dx=1.0)
    assert a3.get_potential_energy() == pytest.approx(e3, rel=1e-14)
    assert np.abs(a3.get_forces()[:, 2]).max() > 0
    a2 = periodic_box(8, dx=1.0, jitter=0.2, seed=1)
    assert FanCalculator(h=2.6, dx=1.0).get_potential_energy(a2) == pytest.approx(
        FanCalculator(h=2.6, dx=1.0, dim=2).get_potential_energy(a2), rel=1e-14)


@pytest.mark.parametrize("calc_dim, atoms_dim, match", [
    (2, 3, r"info\['dim'\] = 3 .* but dim=2"),
    (3, 2, r"info\['dim'\] = 2 .* but dim=3"),
])
def test_fan_calculator_refuses_a_mismatch(calc_dim, atoms_dim, match):
    atoms = periodic_box(6, dx=1.0, dim=atoms_dim, jitter=0.2, seed=1)
    with pytest.raises(ValueError, match=match):
        FanCalculator(h=2.6, dx=1.0, dim=calc_dim).get_potential_energy(atoms)
    atoms.info.pop("dim")  # the geometry alone says it too
    with pytest.raises(ValueError, match=rf"{'periodic along z' if atoms_dim == 3 else 'lies at z = 0'}"):
        FanCalculator(h=2.6, dx=1.0, dim=calc_dim).get_potential_energy(atoms)


def test_quality_infers_the_dimension():
    """quality_summary on 3D atoms without dim: the dim=3 numbers, finite (was all outside, NaN)."""
    box = Box((0, 0, 0), (1, 1, 1))
    atoms = fill(box, 1 / 8, jitter=0.1, seed=0)
    ours = quality_summary(atoms, h=2.6 / 8, dx=1 / 8, domain=box)
    assert ours == quality_summary(atoms, h=2.6 / 8, dx=1 / 8, domain=box, dim=3)
    assert ours["n_outside"] == 0 and all(v is not None and np.isfinite(v) for v in ours.values())
    with pytest.raises(ValueError, match="domain is 3D but dim=2"):
        quality_summary(atoms, h=2.6 / 8, dx=1 / 8, domain=box, dim=2)


def test_lammps_io_uses_the_same_rule():
    from lammps_io.box import infer_dim, lammps_box

    for atoms in (periodic_box(4, dim=2), periodic_box(3, dim=3), fill(Circle((0, 0), 0.5), 0.1)):
        assert infer_dim(atoms) == resolve_dim(atoms)
    off = _no_info(periodic_box(4, dim=2))
    off.positions[:, 2] = 0.25
    with pytest.raises(ValueError) as ours:
        resolve_dim(off)
    with pytest.raises(ValueError) as theirs:
        lammps_box(off)
    assert str(ours.value) == str(theirs.value)


def test_lattice_analysis_uses_the_same_rule():
    from ase_sphrelax.analysis import classify_lattice

    atoms = periodic_box((4, 4), dx=1.0, lattice="hexagonal")
    assert classify_lattice(atoms) == classify_lattice(atoms, dim=2)
    with pytest.raises(ValueError, match=r"info\['dim'\] = 2"):
        classify_lattice(atoms, dim=3)


@pytest.mark.parametrize("z", [0.0, 1e-14, -1e-14, 1e-3])
def test_the_calculators_one_pass_gives_the_rules_verdicts(z):
    """SPHCalculator.resolve_dim looks at the positions once (finite, y = 0, z = 0) and hands that to
    checks.resolve_dim: the verdicts and prepare's positions are those of the rule's own look (round-off z
    accepted and zeroed in a copy, a real z refused), for 2D, 1D and flat 3D sets."""
    a2 = fill(Circle((0, 0), 0.5), 0.1, jitter=0.2, seed=3)
    a2.positions[::7, 2] = z
    calc = FanCalculator(h=0.26, dx=0.1)
    if z == 1e-3:
        with pytest.raises(ValueError, match="needs every particle at z = 0"):
            calc.resolve_dim(a2)
        with pytest.raises(ValueError, match="needs every particle at z = 0"):
            resolve_dim(a2)
        return
    assert calc.resolve_dim(a2) == resolve_dim(a2) == 2
    r_pc, _ = calc.prepare(a2, 0.26, 0.026)
    assert np.all(r_pc[:, 2] == 0.0) and (r_pc is a2.positions) == (z == 0.0)
    assert a2.positions[7, 2] == z  # the caller's positions stay as they are
    line = Atoms("X3", positions=[(0, 0, 0), (1, z, 0), (2, 0, z)], cell=[3, 0, 0], pbc=(True, False, False))
    assert FanCalculator(h=1.3, dx=1.0).resolve_dim(line) == resolve_dim(line) == 1
    flat = Atoms("X2", positions=[(0, 0, z), (1, 0, z)])
    for ask in (None, 2, 3):
        assert _verdict(lambda: FanCalculator(h=1.3, dx=1.0, dim=ask).resolve_dim(flat)) == \
            _verdict(lambda: resolve_dim(flat, ask, name="dim"))


def _verdict(call):
    try:
        return call()
    except ValueError as error:
        return str(error)
