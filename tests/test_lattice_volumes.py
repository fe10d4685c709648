"""Characteristic volumes and predicted patterns against Fan et al. Table 2 (Sec. 5.1, Appendix B)."""
import math

import numpy as np
import pytest

from ase_sphrelax.analysis import (
    PATTERNS_2D,
    characteristic_volume,
    characteristic_volume_of_atoms,
    characteristic_volume_of_cell,
    lattice_kernel_sum,
    pattern_cell,
    predict_pattern,
)
from ase_sphrelax.kernels import get_kernel

# Fan et al., Table 2: h/dx, v_hexagon, v_square, v_diamond, v_rectangle, v_parallelogram, pattern, k, r
TABLE2 = """
1.5 0.878 0.8548 0.872 0.8548 0.872 H
1.55 0.8982 0.8779 0.8927 0.8779 0.8927 H
1.6 0.9138 0.8975 0.909 0.8975 0.909 H
1.65 0.9257 0.9137 0.9217 0.9137 0.9217 H
1.7 0.9346 0.9269 0.9314 0.9269 0.9314 H
1.75 0.9413 0.9373 0.9389 0.9373 0.9389 H
1.8 0.9465 0.9455 0.9449 0.9455 0.9455 H
1.85 0.9508 0.9519 0.9499 0.9519 0.9519 S
1.9 0.9546 0.9568 0.9543 0.9568 0.9568 S
1.95 0.9582 0.9606 0.9583 0.9606 0.9606 S
2.0 0.9616 0.9638 0.9621 0.9638 0.9638 S
2.05 0.965 0.9664 0.966 0.9664 0.9664 S
2.1 0.9684 0.9688 0.9695 0.9689 0.9696 P 1.18 0.42
2.15 0.9716 0.9711 0.9726 0.9714 0.9727 P 1.19 0.42
2.2 0.9747 0.9734 0.9752 0.9737 0.9753 P 1.17 0.42
2.25 0.9777 0.9756 0.9777 0.9758 0.9777 H
2.3 0.9805 0.9779 0.9803 0.9779 0.9803 H
2.35 0.9831 0.9801 0.9826 0.9801 0.9826 H
2.4 0.9854 0.9824 0.9847 0.9824 0.9847 H
2.45 0.9873 0.9845 0.9865 0.9845 0.9865 H
2.5 0.9889 0.9864 0.9881 0.9864 0.9881 H
2.55 0.9902 0.9881 0.9894 0.9881 0.9894 H
2.6 0.9912 0.9896 0.9904 0.9896 0.9904 H
2.65 0.992 0.9909 0.9913 0.9909 0.9913 H
2.7 0.9926 0.9919 0.992 0.9919 0.992 H
2.75 0.993 0.9927 0.9926 0.9927 0.9927 H
2.8 0.9934 0.9934 0.9931 0.9934 0.9934 P 1.0 0.86
2.85 0.9937 0.9939 0.9936 0.9939 0.9939 P 1.0 0.82
2.9 0.994 0.9943 0.994 0.9943 0.9944 P 1.0 0.19
2.95 0.9943 0.9946 0.9944 0.9946 0.9947 P 1.0 0.79
3.0 0.9946 0.9949 0.9949 0.9949 0.995 P 1.0 0.23
3.05 0.995 0.9951 0.9953 0.9951 0.9953 P 1.11 0.53
3.1 0.9954 0.9954 0.9957 0.9954 0.9957 P 1.14 0.44
3.15 0.9958 0.9956 0.996 0.9957 0.9961 P 1.15 0.44
3.2 0.9962 0.9959 0.9963 0.9961 0.9963 P 1.15 0.44
3.25 0.9965 0.9961 0.9965 0.9963 0.9966 P 1.12 0.44
3.3 0.9969 0.9964 0.9968 0.9966 0.9968 H
3.35 0.9972 0.9967 0.9971 0.9968 0.9971 H
3.4 0.9975 0.997 0.9973 0.997 0.9973 H
3.45 0.9977 0.9972 0.9975 0.9972 0.9975 H
3.5 0.9979 0.9975 0.9977 0.9975 0.9977 H
"""
NAMES = {"H": "hexagonal", "S": "square", "P": "parallelogram"}
ROWS = []
for line in TABLE2.strip().splitlines():
    f = line.split()
    ROWS.append(dict(h=float(f[0]), hexagonal=float(f[1]), square=float(f[2]), diamond=float(f[3]),
                     rectangular=float(f[4]), parallelogram=float(f[5]), pattern=NAMES[f[6]],
                     k=float(f[7]) if len(f) > 7 else None, r=float(f[8]) if len(f) > 8 else None))
H_ALL = [row["h"] for row in ROWS]
ROW = {row["h"]: row for row in ROWS}
# the paper's diamond optimum is one unit low in the 4th digit where the diamond optimum is interior
# (k = 2.24-2.39): under-resolved search in the paper (see lattice.py docstring)
DIAMOND_DIFFERS = {2.1: 0.9696, 2.15: 0.9727, 2.2: 0.9753, 3.15: 0.9961, 3.25: 0.9966}


def printed(value):
    return round(float(value), 4)


def test_facts_reference_values():
    """FACTS.md: hexagonal 0.878028 and square 0.854838 at h = 1.5; 0.991235 / 0.989635 at 2.6."""
    assert characteristic_volume("hexagonal", 1.5)[0] == pytest.approx(0.878028, abs=5e-7)
    assert characteristic_volume("square", 1.5)[0] == pytest.approx(0.854838, abs=5e-7)
    assert characteristic_volume("hexagonal", 2.6)[0] == pytest.approx(0.991235, abs=5e-7)
    assert characteristic_volume("square", 2.6)[0] == pytest.approx(0.989635, abs=5e-7)


def test_lattice_sum_brute_force():
    """Numba lattice sum equals a plain sum over a generous range of lattice vectors."""
    kern = get_kernel("wendland_c2", 2)
    cell = np.array([[0.93, 0.0], [0.41, 1.0 / 0.93]])
    m = np.arange(-12, 13)
    m1, m2 = np.meshgrid(m, m)
    pts = m1.reshape(-1, 1) * cell[0] + m2.reshape(-1, 1) * cell[1]
    brute = kern.w(np.linalg.norm(pts, axis=1), 2.9).sum()
    assert lattice_kernel_sum(cell, 2.9) == pytest.approx(brute, rel=1e-13)
    # the basis path (numpy) agrees with the one-site path (numba)
    assert lattice_kernel_sum(cell, 2.9, basis_bv=[[0.0, 0.0]]) == pytest.approx(brute, rel=1e-13)


def test_vc_invariant_under_basis_change_and_rotation():
    cell, _ = pattern_cell("parallelogram", {"k": 1.12, "r": 0.37})
    v = characteristic_volume_of_cell(cell, 2.7)
    unimodular = np.array([[2, 1], [1, 1]])
    c, s = math.cos(0.7), math.sin(0.7)
    rot = np.array([[c, -s], [s, c]])
    assert characteristic_volume_of_cell(unimodular @ cell @ rot.T * 3.0, 2.7) == pytest.approx(v, rel=1e-12)
    # a 2-site supercell gives the same v_c
    sup = np.array([2 * cell[0], cell[1]])
    assert characteristic_volume_of_cell(sup, 2.7, basis_bv=[[0, 0], cell[0]]) == pytest.approx(v, rel=1e-12)


@pytest.mark.parametrize("h", H_ALL)
def test_hexagonal_square_rectangular_columns(h):
    row = ROW[h]
    for name in ("hexagonal", "square", "rectangular"):
        assert printed(characteristic_volume(name, h)[0]) == row[name], name


@pytest.mark.parametrize("h", H_ALL)
def test_parallelogram_diamond_and_pattern_columns(h):
    """Every row: parallelogram column, Pattern column with its k, r; diamond except 5 rows."""
    row = ROW[h]
    winner, values = predict_pattern(h, return_values=True)
    assert winner == row["pattern"]
    assert printed(values["parallelogram"][0]) == row["parallelogram"]
    assert printed(values["diamond"][0]) == DIAMOND_DIFFERS.get(h, row["diamond"])
    for name in ("hexagonal", "square", "rectangular"):
        assert printed(values[name][0]) == row[name]
    if winner == "parallelogram":
        k, r = values["parallelogram"][1]["k"], values["parallelogram"][1]["r"]
        assert 0.0 <= r <= 0.5 / k + 1e-12
        assert k == pytest.approx(row["k"], abs=0.011)
        # the paper prints either mirror branch r or 1/k - r
        assert min(abs(r - row["r"]), abs(1.0 / k - r - row["r"])) <= 0.011


def test_table1_ranges():
    """Table 1 boundaries: hexagonal up to 1.8, square 1.85-2.05, parallelogram 2.1-2.2, ..."""
    for h, name in [(1.8, "hexagonal"), (1.85, "square"), (2.05, "square"), (2.1, "parallelogram"),
                    (2.25, "hexagonal"), (2.75, "hexagonal"), (3.25, "parallelogram"), (3.3, "hexagonal")]:
        assert predict_pattern(h) == name, h


def test_bravais_convention_names_the_true_optimum():
    """The global optimum at 2.15 / 2.9 / 3.15 is centred rectangular, at 3.05 oblique."""
    for h, name in [(1.6, "hexagonal"), (2.0, "square"), (2.15, "diamond"), (2.9, "diamond"),
                    (3.05, "parallelogram"), (3.15, "diamond"), (3.4, "hexagonal")]:
        winner, values = predict_pattern(h, convention="bravais", return_values=True)
        assert winner == name, h
        # the global maximum is at least every Fan-convention column
        for n in PATTERNS_2D:
            assert values["parallelogram"][0] >= characteristic_volume(n, h)[0] - 1e-12
    # at 2.9 the optimum is a rhombus: |a1| = |a2|, outside the paper's k >= 1.005
    _, values = predict_pattern(2.9, convention="bravais", return_values=True)
    cell, _ = pattern_cell("diamond", values["diamond"][1])
    assert values["diamond"][0] == pytest.approx(values["parallelogram"][0], rel=1e-10)
    assert values["parallelogram"][1]["k"] < 1.0


def test_paper_parallelogram_is_centred_at_2_15():
    """Table 2's 'Parallelogram k=1.19, r=0.42' satisfies r = 1/(2k): a centred rectangular lattice."""
    v_par, p = characteristic_volume("parallelogram", 2.15)
    assert p["r"] == pytest.approx(0.5 / p["k"], abs=1e-5)
    v_dia, _ = characteristic_volume("diamond", 2.15)
    assert v_dia == pytest.approx(v_par, rel=1e-9)


def test_vc_of_atoms_matches_pattern():
    from ase import Atoms

    cell, _ = pattern_cell("diamond", {"k": 2.4})
    full = np.eye(3)
    full[:2, :2] = cell * 1.7  # any scale: h is in units of (V/N)^(1/2)
    atoms = Atoms("X", positions=[[0, 0, 0]], cell=full, pbc=(True, True, False)).repeat((3, 2, 1))
    v = characteristic_volume_of_atoms(atoms, 2.6)
    assert v == pytest.approx(characteristic_volume_of_cell(cell, 2.6), rel=1e-12)


def test_3d_named_lattices_and_general():
    from ase.build import bulk

    for name, atoms in [("fcc", bulk("Cu", "fcc", a=1.3, cubic=True)), ("bcc", bulk("Fe", "bcc", a=1.1, cubic=True)),
                        ("hcp", bulk("Mg", "hcp", a=1.0, c=math.sqrt(8 / 3)))]:
        v = characteristic_volume(name, 2.6, dim=3)[0]
        assert characteristic_volume_of_atoms(atoms.repeat(2), 2.6, dim=3) == pytest.approx(v, rel=1e-12)
    # h = 2.0: the simple cubic lattice is the best one-atom lattice (Fan Sec. 5.2, last paragraph)
    assert predict_pattern(2.0, dim=3) == "sc"
    v_gen = characteristic_volume("general", 2.6, dim=3)[0]
    assert v_gen >= max(characteristic_volume(n, 2.6, dim=3)[0] for n in ("sc", "bcc", "fcc")) - 1e-12


@pytest.mark.parametrize("bad", [dict(pattern="triangle"), dict(h_over_dx=-1.0), dict(h_over_dx="2"),
                                 dict(dim=4), dict(convention="paper"), dict(pattern="fcc")])
def test_bad_input(bad):
    kwargs = dict(pattern="square", h_over_dx=2.0, dim=2, convention="fan")
    kwargs.update(bad)
    with pytest.raises((ValueError, TypeError)):
        characteristic_volume(**kwargs)
