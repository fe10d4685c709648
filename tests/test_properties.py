"""Property tests (issue 22 item 5, all but gamma): forces = -grad E on random configurations with
near-coincident pairs and particles on and near boundaries; extxyz and LAMMPS data round trips; every CLI
command given random bad arguments exits 2 with one line.

Fixed ``max_examples``, ``deadline=None``, ``database=None`` (CI needs no example database)."""
import numpy as np
import pytest
from ase.calculators.calculator import all_changes
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_calculator_contract import METHODS

from ase_sphrelax import FanCalculator
from ase_sphrelax.build import fill

PROPERTY = settings(max_examples=4, deadline=None, database=None,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])


def _energy(calc, atoms):
    calc.calculate(atoms, ["energy"], all_changes)
    return calc.results["energy"]


def _check_gradient(calc, atoms, idx, dim, rel_atol=1e-6, eps=None):
    """Central differences of E at the particles ``idx`` against the forces (step ``eps``, default 1e-5 x the
    spacing; at a close pair it must be small against the pair's distance, over which the force varies)."""
    calc.calculate(atoms, ["energy", "forces"], all_changes)
    forces = calc.results["forces"].copy()
    scale = float(np.ptp(atoms.positions[:, :dim], axis=0).max()) / max(len(atoms), 1) ** (1 / dim)
    eps = 1e-5 * scale if eps is None else eps
    for i in idx:
        for c in range(dim):
            moved = atoms.copy()
            moved.positions[i, c] += eps
            e_plus = _energy(calc, moved)
            moved.positions[i, c] -= 2 * eps
            e_minus = _energy(calc, moved)
            numeric = -(e_plus - e_minus) / (2 * eps)
            assert numeric == pytest.approx(forces[i, c], abs=rel_atol * np.abs(forces).max() + 1e-300), (i, c)


def _support(calc, atoms, dim):
    h = calc.parameters.get("h")
    if isinstance(h, (int, float)):
        return float(h)
    return 2.0 * float(np.ptp(atoms.positions[:, :dim], axis=0).max()) / len(atoms) ** (1 / dim)


# LAMMPS: test_lammps_fan's own checks; the non-conservative forms (ParVI's pressure forms) have no energy
CONSERVATIVE = [name for name in METHODS if name != "fan lammps" and METHODS[name].make().conservative]
CLOSE_PAIR_CASES = CONSERVATIVE  # ALARIC included: its forces are exact at close pairs (issue 20 item 1)


@pytest.mark.parametrize("name", CLOSE_PAIR_CASES)
@PROPERTY
@given(data=st.data())
def test_forces_are_minus_the_gradient_with_a_near_coincident_pair(name, data):
    method = METHODS[name]
    dim = data.draw(st.sampled_from(method.dims), label="dim")
    atoms, calc = method.atoms(dim), method.make()
    assert calc.conservative
    rng = np.random.default_rng(data.draw(st.integers(0, 2**31), label="seed"))
    h = _support(calc, atoms, dim)
    i, j = rng.choice(len(atoms), 2, replace=False)
    u = rng.normal(size=dim)
    atoms.positions[j, :dim] = atoms.positions[i, :dim] + 1e-4 * h * u / np.linalg.norm(u)
    others = rng.choice(len(atoms), 2, replace=False)
    # step 1e-7 h: truncation ~ (step / 1e-4 h)^2 = 1e-6 and round-off ~ 1e-7 relative; 1e-5 still tells a
    # floored force (35x off, issue 20) from the exact one
    _check_gradient(calc, atoms, [i, j, *others], dim, rel_atol=max(method.fd_atol, 1e-5), eps=1e-7 * h)


TRAPEZOID = np.array([[0, 1], [0, 0], [1, 0], [1.5, 1.0]])


def _bounded_cases():
    from ase_sphrelax import BIPICalculator
    from ase_sphrelax.domains import Circle, Polygon

    circle = Circle((0.5, 0.5), 0.2)
    polygon = Polygon([TRAPEZOID])
    dx_c, dx_p = 1 / 32, 1 / 16
    return {
        "fan circle": (lambda: FanCalculator(h=2.6 * dx_c, dx=dx_c, domain=circle), circle, dx_c),
        "bipi trapezoid": (lambda: BIPICalculator(h=4 * dx_p, dx=dx_p, boundary=polygon), polygon, dx_p),
    }


@pytest.mark.parametrize("case", ["fan circle", "bipi trapezoid"])
@PROPERTY
@given(seed=st.integers(0, 2**31), depth=st.sampled_from([0.0, 1e-9, 1e-4, 0.1, 0.45]),
       k=st.integers(1, 3))
def test_forces_are_minus_the_gradient_on_and_near_the_boundary(case, seed, depth, k):
    """``k`` particles put at distance ``depth dx`` inside the boundary (0: on it)."""
    make, domain, dx = _bounded_cases()[case]
    rng = np.random.default_rng(seed)
    atoms = fill(domain, dx, jitter=0.2, seed=seed % 1000)
    idx = rng.choice(len(atoms), k, replace=False)
    r_pd = atoms.positions[idx, :2]
    phi, normal = domain.phi_and_normal(r_pd)
    atoms.positions[idx, :2] = r_pd - (np.asarray(phi) + depth * dx)[:, None] * np.asarray(normal)[:, :2]
    assert np.allclose(domain.phi(atoms.positions[idx, :2]), -depth * dx, atol=1e-12)
    _check_gradient(make(), atoms, list(idx) + [int(rng.integers(len(atoms)))], 2)


# -- round trips: extxyz and LAMMPS data keep positions, cell, pbc and dim --------------------------------
def _random_atoms(dim, n, periodic, rng):
    from ase import Atoms

    lengths = rng.uniform(0.5, 3.0, dim)
    pos = np.zeros((n, 3))
    pos[:, :dim] = rng.uniform(0, 1, (n, dim)) * lengths
    cell = np.diag(list(lengths) + [1.0] * (3 - dim))
    atoms = Atoms(f"H{n}", positions=pos, cell=cell, pbc=[periodic] * dim + [False] * (3 - dim))
    atoms.info["dim"] = dim
    return atoms


@PROPERTY
@given(dim=st.sampled_from([1, 2, 3]), n=st.integers(1, 40), periodic=st.booleans(), seed=st.integers(0, 2**31))
def test_extxyz_round_trip_keeps_positions_cell_pbc_and_dim(tmp_path, dim, n, periodic, seed):
    from ase.io import read, write

    from ase_sphrelax.checks import resolve_dim

    atoms = _random_atoms(dim, n, periodic, np.random.default_rng(seed))
    path = tmp_path / "a.extxyz"
    write(path, atoms, format="extxyz")
    back = read(path)
    # ASE's extxyz writes positions as %16.8f: kept to half a unit of the 8th decimal, no better
    np.testing.assert_allclose(back.positions, atoms.positions, rtol=0, atol=5.0000001e-9)
    np.testing.assert_allclose(back.cell.array, atoms.cell.array, rtol=0, atol=1e-12)
    assert list(back.pbc) == list(atoms.pbc)
    assert back.info["dim"] == dim and resolve_dim(back) == dim


@PROPERTY
@given(dim=st.sampled_from([1, 2, 3]), n=st.integers(1, 40), periodic=st.booleans(), seed=st.integers(0, 2**31))
def test_lammps_data_round_trip_keeps_positions_cell_pbc_and_dim(tmp_path, dim, n, periodic, seed):
    """Read back by ASE's lammps-data reader: positions (up to the box shift of an open set), the cell
    lengths, the boundary letters the deck uses (pbc) and the dimension written in the header."""
    from ase.io import read

    from lammps_io.data_file import write_data

    atoms = _random_atoms(dim, n, periodic, np.random.default_rng(seed))
    path = tmp_path / "a.data"
    box = write_data(atoms, path, margin=None if periodic else 0.25)
    back = read(path, format="lammps-data", atom_style="atomic", units="metal")  # metal: lengths unconverted
    order = np.argsort(back.arrays.get("id", np.arange(1, n + 1)))
    r_back = back.positions[order]
    shift = r_back[0] - atoms.positions[0] if not periodic else np.zeros(3)
    np.testing.assert_allclose(r_back[:, :dim] - shift[:dim], atoms.positions[:, :dim], rtol=0, atol=1e-9)
    lengths = np.diag(back.cell.array)[:dim]
    if periodic:
        np.testing.assert_allclose(lengths, np.diag(atoms.cell.array)[:dim], rtol=1e-12)
    assert box.boundary.split()[:dim] == ["p" if periodic else "f"] * dim
    assert f"dim {dim})" in path.read_text().splitlines()[0]


# -- every command: random bad arguments exit 2 with one line ---------------------------------------------
# options whose values are checked before any work, and a valid base command line for each command
BAD_NUMBERS = ["abc", "nan", "inf", "-inf", "-1", "0x", "", "1e999", "--"]
CHECKED_OPTIONS = {
    "relax": (["--steps", "0"], ["--dx", "--h", "--steps", "--fmax", "--fmax-rel", "--c", "--max-particles",
                                 "--jitter", "--seed", "--dim"]),
    "pack": (["--boundary", "{square}", "--dx", "0.2"], ["--dx", "--h", "--h-paper", "--tol", "--window",
                                                         "--max-steps-2a", "--max-steps-2c", "--max-particles"]),
    "density": (["--max-steps", "1"], ["--n", "--split", "--max-steps", "--eps-min", "--dim", "--polish-steps",
                                      "--seed"]),
    "sample": (["--target", "gaussian", "--steps", "1"], ["--n", "--dim", "--alpha", "--c0", "--steps",
                                                          "--max-steps", "--init-scale", "--seed", "--friction"]),
    "lattice": (["--h", "2.6"], ["--h", "--dim", "--seed"]),
    "export": (["{input}", "{output}"], ["--dx", "--rho0", "--h", "--units", "--format", "--atom-style"]),
}


@pytest.fixture(scope="module")
def cli_files(tmp_path_factory):
    from ase_sphrelax.build import periodic_box

    folder = tmp_path_factory.mktemp("cli")
    (folder / "square.edges").write_text("0 0 1 0\n1 0 1 1\n1 1 0 1\n0 1 0 0\n")
    periodic_box((4, 3), dx=0.5, dim=2, jitter=0.1, seed=0).write(folder / "in.extxyz")
    return folder


@pytest.mark.parametrize("command", list(CHECKED_OPTIONS))
@settings(max_examples=6, deadline=None, database=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_every_command_refuses_random_bad_arguments_in_one_line(command, data, cli_files, tmp_path, capsys):
    from ase_sphrelax.cli import main

    base, options = CHECKED_OPTIONS[command]
    names = dict(square=cli_files / "square.edges", input=cli_files / "in.extxyz", output=tmp_path / "out.data")
    argv = [command] + [a.format(**names) for a in base]
    kind = data.draw(st.sampled_from(["value", "unknown", "missing"]), label="kind")
    if kind == "value":
        option = data.draw(st.sampled_from(options), label="option")
        bad = data.draw(st.sampled_from(BAD_NUMBERS), label="value")
        if bad == "-1" and option in ("--seed", "--friction"):
            bad = "abc"  # -1 is a valid seed; a negative friction is refused, but after the target's set-up
        argv += [option, bad] if bad != "--" else [option]
    elif kind == "unknown":
        argv += ["--" + data.draw(st.text("abcdefghijklmnopqrstuvwxyz", min_size=3, max_size=12), label="name")
                 + "-bogus"]
    elif command in ("pack", "sample", "lattice", "export"):  # a required argument left out
        argv = [command]
    else:  # relax and density require nothing
        argv += ["--bogus"]
    argv += ["--out", str(tmp_path / "o")] if command not in ("lattice", "export") else []
    capsys.readouterr()
    try:
        code = main(argv)
    except SystemExit as done:
        code = done.code
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2, (argv, err)
    assert len(err) == 1 and "Traceback" not in err[0] and "error" in err[0], (argv, err)
