"""ALARIC: inconsistent inputs are caught before any step (issue 22 problems 7, 10, 11)."""
import numpy as np
import pytest
from ase import Atoms

from ase_sphrelax import ALARICCalculator
from ase_sphrelax.models import alaric as model


def _periodic_line(n=40):
    pos = np.zeros((n, 3))
    pos[:, 0] = (np.arange(n) + 0.5) / n * 2.0
    return Atoms(numbers=np.zeros(n, int), positions=pos, cell=[2.0, 0, 0], pbc=[True, False, False])


@pytest.mark.parametrize("form", ["log", "squares"])
@pytest.mark.parametrize("dim", [1, 2])
def test_wrong_sign_target_gradient_is_refused_at_the_first_evaluation(form, dim):
    density, gradient = model.eq46(0.3)
    n_side = 40 if dim == 1 else 10
    grid = np.stack(np.meshgrid(*[np.arange(n_side)] * dim, indexing="ij"), axis=-1).reshape(-1, dim)
    pos = np.zeros((len(grid), 3))
    pos[:, :dim] = (grid + 0.5) / n_side * 2.0
    atoms = Atoms(numbers=np.zeros(len(pos), int), positions=pos, cell=np.eye(3) * 2.0,
                  pbc=[True] * dim + [False] * (3 - dim))
    atoms.calc = ALARICCalculator(target_density=density, target_gradient=lambda x: -gradient(x), dim=dim, form=form,
                                  origin=[-1.0] * dim)
    with pytest.raises(ValueError, match=r"target_gradient is not the gradient of target_density.*wrong sign"):
        atoms.get_forces()


def test_gradient_of_another_function_is_refused_and_a_right_one_accepted():
    density, gradient = model.eq46(0.3)
    atoms = _periodic_line()
    atoms.calc = ALARICCalculator(target_density=lambda x: density(0.5 * x), target_gradient=gradient, dim=1,
                                  origin=[-1.0])
    with pytest.raises(ValueError, match="target_gradient is not the gradient"):
        atoms.get_forces()
    atoms.calc = ALARICCalculator(target_density=density, target_gradient=gradient, dim=1, origin=[-1.0])
    assert np.all(np.isfinite(atoms.get_forces()))


# -- runs that end wrong say so (issue 22 problems 4 and 10) ----------------------------------------------
def _relax(target, n=33, **kw):
    from ase_sphrelax.checks import NotConvergedWarning
    from ase_sphrelax.drivers.alaric_dynamics import relax_density, start_atoms

    atoms, origin, _ = start_atoms(n, 1)
    with pytest.warns(NotConvergedWarning) as record:
        result = relax_density(atoms, target, 1, origin=origin, polish=False, **kw)
    return result, str(record[0].message)


def test_particles_left_where_the_target_is_zero_are_flagged():
    result, message = _relax(lambda x: np.maximum(0.0, np.sin(np.pi * x[:, 0])), max_steps=20000)
    assert not result["converged"]
    assert result["diagnostics"]["zero_region_particles"] > 0
    assert "sit where rho* = 0" in result["convergence_reason"] and "rho* = 0" in message


def test_a_1e6_contrast_with_too_dense_tails_is_flagged_beside_a_small_epsilon():
    result, _ = _relax(lambda x: 1e-6 + np.exp(-x[:, 0] ** 2 / 0.02), max_steps=20000)
    assert not result["converged"]
    tails = [r for r in result["diagnostics"]["regions"] if r["target_range"][1] <= 1e-4]
    assert tails and max(r["rms_relative_error"] for r in tails) > 1.0
    assert result["diagnostics"]["max_relative_error"] > 1.0
    assert "rho / rho* - 1 has RMS" in result["convergence_reason"]


def test_density_diagnostics_by_hand():
    rho = np.array([1.0, 2.0, 0.5, 3.0])
    target = np.array([1.0, 1.0, 1e-3, 0.0])
    n = np.ones(4)
    d = model.density_diagnostics(rho, target, n)
    assert d["zero_target_particles"] == 1
    assert d["max_relative_error"] == pytest.approx(499.0)
    assert [r["n"] for r in d["regions"]] == [2, 1]
    assert d["regions"][0]["rms_relative_error"] == pytest.approx(np.sqrt(0.5))
    ok, reason = model.convergence_verdict("epsilon", model.density_diagnostics(rho[:2], target[:2], n[:2]))
    assert ok and reason == "stopped by epsilon"
    # one particle off by more than its target (Eq. 48's particle in a dip) passes, two do not
    assert d["off_by_more_than_target"] == 1
    assert model.convergence_verdict("epsilon", model.density_diagnostics(rho[:3], target[:3], n[:3]))[0]
    rho2, target2 = np.array([1.0, 3.0, 0.5, 0.5]), np.array([1.0, 1.0, 1e-3, 1e-3])
    ok, reason = model.convergence_verdict("epsilon", model.density_diagnostics(rho2, target2, np.ones(4)))
    assert not ok and "has RMS" in reason


def _cli(*args):
    import subprocess
    import sys

    return subprocess.run([sys.executable, "-m", "ase_sphrelax.cli", "density", *args], capture_output=True, text=True,
                          timeout=900)


def test_degenerate_two_particle_run_is_not_reported_as_converged(tmp_path):
    import json

    proc = _cli("--n", "2", "--split", "0", "--out", str(tmp_path / "two"))
    summary = json.loads((tmp_path / "two" / "summary.json").read_text())
    assert summary["converged"] is False
    assert "degenerate" in summary["convergence_reason"] and "Eq. 48" in summary["convergence_reason"]
    assert "NOT CONVERGED" in proc.stdout


def test_dim1_domain_is_refused(tmp_path):
    proc = _cli("--dim", "1", "--domain", "circle", "--out", str(tmp_path / "x"))
    assert proc.returncode == 2
    assert "--domain is for --dim 2 or 3" in proc.stderr and "Traceback" not in proc.stderr


def test_1d_output_exports_to_lammps_in_the_cell_frame(tmp_path):
    """relaxed.extxyz holds the target frame [-1, 1) with info['origin'] = [-1]; the LAMMPS data lie in the cell [0, 2)
    at x + 1 (before, they were written at x, shifted by half a period)."""
    from ase.io import read

    from lammps_io.cli import cli_export

    out = tmp_path / "line"
    proc = _cli("--n", "33", "--split", "0", "--max-steps", "30", "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    atoms = read(out / "relaxed.extxyz")
    assert atoms.info["origin"] == [-1.0] or list(np.ravel(atoms.info["origin"])) == [-1.0]
    cli_export(out / "relaxed.extxyz", tmp_path / "line.data", atom_style="sph")
    lines = (tmp_path / "line.data").read_text().splitlines()
    start = lines.index("Atoms # sph") + 2
    x = np.array([float(line.split()[5]) for line in lines[start:start + len(atoms)]])
    ids = np.array([int(line.split()[0]) for line in lines[start:start + len(atoms)]])
    np.testing.assert_allclose(np.sort(x), np.sort(np.mod(atoms.positions[:, 0] + 1.0, 2.0)), atol=1e-9)
    assert x.min() >= 0.0 and x.max() < 2.0 and len(set(ids)) == len(atoms)


def test_a_particle_at_an_isolated_zero_of_the_target_is_not_a_zero_region():
    """Eq. 46 with Delta = 0 has rho*(0) = 0; the equispaced odd start puts a particle there (Fig. 8's bottom of
    the well, the situation of Eq. 48): counted in zero_target_particles, not as left in a zero region."""
    from ase_sphrelax.drivers.alaric_dynamics import relax_density, start_atoms

    density, gradient = model.eq46(0.0)
    atoms, origin, _ = start_atoms(33, 1)
    result = relax_density(atoms, density, 1, target_gradient=gradient, origin=origin, polish=False, max_steps=20000)
    d = result["diagnostics"]
    assert d["zero_target_particles"] == 1 and d["zero_region_particles"] == 0
    assert result["converged"] and "rho* = 0" not in result["convergence_reason"]


def test_density_exit_status_says_whether_the_run_converged(tmp_path):
    """Issue 22 Deliver 1: exit 0 only when the run reached its own stopping rule or the user fixed its length
    (--max-steps); a degenerate run of the default length exits 3 (EXIT_NOT_CONVERGED)."""
    from ase_sphrelax.cli.common import EXIT_NOT_CONVERGED

    default = _cli("--n", "2", "--split", "0", "--out", str(tmp_path / "default"))
    assert default.returncode == EXIT_NOT_CONVERGED, default.stderr
    assert "not converged" in default.stderr and "degenerate" in default.stderr
    fixed = _cli("--n", "2", "--split", "0", "--max-steps", "50", "--out", str(tmp_path / "fixed"))
    assert fixed.returncode == 0, fixed.stderr
    assert "warning: not converged" in fixed.stderr


def test_background_and_finish_are_checked():
    density, _ = model.eq46(0.3)
    with pytest.raises(ValueError, match="background must be a finite number >= 0"):
        ALARICCalculator(target_density=density, dim=1, form="squares", background=-1.0)
    with pytest.raises(ValueError, match="background is for form='squares' or 'paper'"):
        ALARICCalculator(target_density=density, dim=1, background=0.1)
    from ase_sphrelax.drivers.alaric_dynamics import relax_density

    with pytest.raises(ValueError, match="finish must be 'squares' or 'none'"):
        relax_density(_periodic_line(), density, 1, finish="log", origin=[-1.0])
