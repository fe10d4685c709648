"""sphrelax density: the command the checks use, its outputs, and one-line usage errors."""
import json
import subprocess
import sys

import numpy as np
import pytest
from ase.io import read


def _run(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "ase_sphrelax.cli", *args], capture_output=True, text=True, cwd=cwd,
                          timeout=900)


@pytest.mark.slow
def test_density_eq46_delta_01_reaches_1e5(tmp_path):
    """The issue's 'done when': Eq. 46 with Delta = 0.1 and 303 particles (101 split once) reaches eps <= 1e-5."""
    out = tmp_path / "run"
    proc = _run("density", "--profile", "eq46", "--delta", "0.1", "--dim", "1", "--n", "303", "--split", "1",
                "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["epsilon"] <= 1e-5
    assert summary["epsilon"] >= summary["epsilon_teo_min"]  # never below Eq. 48
    atoms = read(out / "relaxed.extxyz")
    assert len(atoms) == 303
    for key in ("h", "rho", "target"):
        assert key in atoms.arrays
    np.testing.assert_allclose(atoms.get_masses(), summary["mass"], rtol=1e-6)  # extxyz keeps 8 decimals
    assert atoms.positions[:, 0].min() >= -1.0 and atoms.positions[:, 0].max() < 1.0
    assert (out / "density.png").stat().st_size > 0
    trace = json.loads((out / "trace.json").read_text())
    assert trace[0]["n"] == 101 and trace[-1]["n"] == 303


def test_density_small_2d_run(tmp_path):
    out = tmp_path / "disc"
    proc = _run("density", "--profile", "eq49", "--p", "2", "--dim", "2", "--n", "400", "--split", "1",
                "--max-steps", "100", "--polish", "--polish-steps", "100", "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["n"] == 400 and np.isfinite(summary["epsilon"]) and summary["epsilon_teo_min"] is None


@pytest.mark.parametrize("args,message", [
    (["--n", "100", "--split", "1"], "not divisible"),
    (["--profile", "nothing"], "--profile must be"),
    (["--profile", "eq49", "--dim", "1"], "is 2D"),
    (["--profile", "math:pi"], "not callable"),
    (["--boundary", "mirror"], "--boundary mirror is for --dim 2 or 3"),
    (["--dim", "2", "--n", "400", "--domain", "box", "--boundary", "mirror"], "--boundary mirror needs a ball"),
])
def test_density_usage_errors(tmp_path, args, message):
    proc = _run("density", *args, "--out", str(tmp_path / "x"))
    assert proc.returncode == 2
    assert message in proc.stderr
    assert "Traceback" not in proc.stderr


def test_export_keeps_each_particles_mass_and_density(tmp_path):
    from ase import Atoms
    from ase.io import write

    from lammps_io.cli import cli_export

    n = 12
    pos = np.zeros((n, 3))
    pos[:, 0] = np.arange(n) * 2.0 / n
    atoms = Atoms(numbers=np.zeros(n, int), positions=pos, cell=[2.0, 0, 0], pbc=[True, False, False])
    atoms.set_masses(np.full(n, 0.125))
    atoms.new_array("rho", np.linspace(0.5, 1.5, n))
    write(tmp_path / "p.extxyz", atoms, format="extxyz")
    cli_export(tmp_path / "p.extxyz", tmp_path / "p.data", atom_style="sph")
    lines = (tmp_path / "p.data").read_text().splitlines()
    mass_line = lines[lines.index("Masses") + 2]
    assert float(mass_line.split()[1]) == pytest.approx(0.125)
    start = lines.index("Atoms # sph") + 2
    rho = [float(line.split()[2]) for line in lines[start:start + n]]
    np.testing.assert_allclose(rho, np.linspace(0.5, 1.5, n), rtol=1e-8)


def test_density_fig13_like_default_run_has_no_pairing(tmp_path):
    """The issue's Fig. 13-like command with every other option at its default (a convex edge file: mirror ghosts):
    epsilon falls well below the truncated-kernel floor (about 1e-2) and no two particles pair (smallest
    nearest-neighbour distance at least half the mean)."""
    from scipy.spatial import cKDTree

    edges = tmp_path / "circle.edges"
    t = 2 * np.pi * np.arange(65) / 64
    x, y = np.cos(t), np.sin(t)
    edges.write_text("".join(f"{x[i]:.17g} {y[i]:.17g} {x[i + 1]:.17g} {y[i + 1]:.17g}\n" for i in range(64)))
    out = tmp_path / "fig13"
    proc = _run("density", "--profile", "uniform", "--dim", "2", "--n", "200", "--split", "0", "--domain", str(edges),
                "--seed", "1", "--max-steps", "300", "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["boundary"] == "mirror"
    assert summary["epsilon"] < 1e-3
    x = read(out / "relaxed.extxyz").positions[:, :2]
    gap = cKDTree(x).query(x, k=2)[0][:, 1]
    assert gap.min() >= 0.5 * gap.mean()
