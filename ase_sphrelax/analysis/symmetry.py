"""Bravais lattice of a (relaxed, noisy) periodic particle arrangement with spglib.

2D (pbc = True, True, False; particles at z = 0): the layer group from
``spglib.get_symmetry_layerdataset(..., aperiodic_dir=2)`` gives one of Fan's
five patterns (Fig. 5): layer groups 1-7 oblique -> ``"parallelogram"``,
8-48 rectangular -> ``"rectangular"`` or, when the symbol starts with ``c``,
``"diamond"`` (centred rectangular), 49-64 ``"square"``, 65-80 ``"hexagonal"``.

3D: the space group gives one of the 14 Bravais lattices as its Pearson
symbol (crystal family letter + centring): ``aP, mP, mS, oP, oS, oI, oF, tP,
tI, hR, hP, cP, cI, cF``; :data:`CUBIC_NAMES` maps the cubic ones to
``sc/bcc/fcc``; :func:`pattern_name_3d` also recognises ``hcp``.

A relaxed cell of ``n`` particles is usually a supercell of the pattern: the
arrangement is accepted as a lattice when spglib finds ``n / max_basis`` pure
translations, and the point symmetry is that of this primitive arrangement.
Relaxation noise is tolerated by trying a ladder of tolerances (relative to
the mean spacing ``(V/N)**(1/d)``): the smallest that finds the lattice, then
the highest symmetry up to ``classify_up_to`` (1e-2) times the spacing.
"""
from __future__ import annotations

import numbers

import numpy as np
import spglib

from ..checks import resolve_dim

__all__ = [
    "LatticeNotFoundError",
    "SYMPREC_LADDER",
    "CUBIC_NAMES",
    "classify_lattice",
    "classify_cell",
    "pattern_name_3d",
    "layer_group_to_pattern",
    "space_group_to_bravais",
]

#: tolerances tried, in units of the mean particle spacing
SYMPREC_LADDER = (1e-5, 1e-4, 1e-3, 3e-3, 1e-2, 3e-2, 0.1)
CUBIC_NAMES = {"cP": "sc", "cI": "bcc", "cF": "fcc"}


# order of the point group of each lattice (2D patterns; 3D Pearson symbols), to rank symmetries
_HOLOHEDRY_ORDER = {"parallelogram": 2, "rectangular": 4, "diamond": 4, "square": 8, "hexagonal": 12,
                    "aP": 2, "mP": 4, "mS": 4, "oP": 8, "oS": 8, "oI": 8, "oF": 8, "hR": 12,
                    "tP": 16, "tI": 16, "hP": 24, "cP": 48, "cI": 48, "cF": 48}


class LatticeNotFoundError(ValueError):
    """No lattice with at most ``max_basis`` particles per primitive cell within tolerance."""


def layer_group_to_pattern(number, symbol):
    """Fan's 2D pattern name of a layer group (number 1-80 and Hermann-Mauguin symbol)."""
    if not 1 <= number <= 80:
        raise ValueError(f"layer group number must be in 1..80, got {number}")
    if number <= 7:
        return "parallelogram"
    if number <= 48:
        return "diamond" if symbol.strip().startswith("c") else "rectangular"
    if number <= 64:
        return "square"
    return "hexagonal"


def space_group_to_bravais(number, symbol):
    """Pearson symbol (``"cF"``, ``"hR"``, ...) of the Bravais lattice of a space group."""
    if not 1 <= number <= 230:
        raise ValueError(f"space group number must be in 1..230, got {number}")
    centring = symbol.strip()[0]
    if number <= 2:
        return "aP"
    if number <= 15:
        family, allowed = "m", "PS"
    elif number <= 74:
        family, allowed = "o", "PSIF"
    elif number <= 142:
        family, allowed = "t", "PI"
    elif number <= 194:
        return "hR" if centring == "R" else "hP"
    else:
        family, allowed = "c", "PIF"
    letter = "S" if centring in "ABC" else centring
    if family == "m" and letter == "I":  # I-centred monoclinic is a C-centred one in another setting
        letter = "S"
    if letter not in allowed:
        raise ValueError(f"unexpected centring {centring!r} for space group {number} {symbol!r}")
    return family + letter


def _check_atoms(atoms, dim):
    from ase import Atoms

    if not isinstance(atoms, Atoms):
        raise TypeError(f"atoms must be an ase.Atoms, got {type(atoms).__name__}")
    if len(atoms) == 0:
        raise ValueError("atoms is empty")
    if dim is not None and (isinstance(dim, bool) or dim not in (2, 3)):
        raise ValueError(f"dim must be 2, 3 or None, got {dim!r}")
    dim = resolve_dim(atoms, dim)  # the package's one rule (None: inferred from the atoms)
    if dim not in (2, 3):
        raise ValueError(f"dim must be 2, 3 or None, got atoms that are {dim}D")
    if not all(atoms.pbc[:dim]):
        raise ValueError(f"atoms must be periodic along the first {dim} axes for dim={dim}, got pbc={atoms.pbc}")
    return int(dim)


def _spglib_cell(atoms, dim):
    n = len(atoms)
    if dim == 2:
        cell2 = atoms.cell.array[:2, :2]
        area = abs(np.linalg.det(cell2))
        if not area > 0:
            raise ValueError("the in-plane cell vectors of a 2D system are degenerate")
        spacing = np.sqrt(area / n)
        z = atoms.positions[:, 2]
        if np.ptp(z) > 1e-6 * spacing:
            raise ValueError("2D atoms must lie in one plane z = const")
        lat = np.zeros((3, 3))
        lat[:2, :2] = cell2
        lat[2, 2] = 10.0 * spacing * max(1.0, np.sqrt(n))
        frac = np.zeros((n, 3))
        frac[:, :2] = np.linalg.solve(cell2.T, atoms.positions[:, :2].T).T
    else:
        vol = abs(atoms.cell.volume)
        if not vol > 0:
            raise ValueError("the cell is degenerate")
        spacing = (vol / n) ** (1.0 / 3.0)
        lat = atoms.cell.array.copy()
        frac = atoms.cell.scaled_positions(atoms.positions)
    frac[:, :dim] %= 1.0
    return (lat, frac, np.ones(n, dtype=int)), spacing


def _dataset(cell, dim, symprec):
    old = spglib.error.OLD_ERROR_HANDLING
    spglib.error.OLD_ERROR_HANDLING = False
    try:
        if dim == 2:
            return spglib.get_symmetry_layerdataset(cell, aperiodic_dir=2, symprec=symprec)
        return spglib.get_symmetry_dataset(cell, symprec=symprec)
    except spglib.error.SpglibError:
        return None
    finally:
        spglib.error.OLD_ERROR_HANDLING = old


def classify_lattice(atoms, symprec=None, dim=None, max_basis=1, return_details=False, classify_up_to=1e-2):
    """Bravais lattice of a periodic particle arrangement.

    Parameters
    ----------
    atoms : ase.Atoms
        Periodic along the first ``dim`` axes (2D: pbc = (True, True, False),
        particles at z = 0). May be any supercell of the pattern.
    symprec : float, optional
        spglib distance tolerance (length units). Default: climb
        :data:`SYMPREC_LADDER` (times the mean spacing ``s``) until the
        arrangement is a lattice, then keep climbing up to
        ``classify_up_to * s`` and report the highest point symmetry seen
        (relaxed cells carry strain noise of order 1e-3; genuine distortions
        smaller than ``classify_up_to`` times the spacing are not resolved).
    dim : {2, 3, None}
        Default: 2 when pbc = (True, True, False), else 3.
    max_basis : int
        Largest accepted number of particles per primitive cell (1: a Bravais
        lattice; 2 accepts e.g. hcp in 3D or honeycomb in 2D).
    classify_up_to : float
        Largest relative tolerance used to *upgrade* the symmetry once a
        lattice is found (default 1e-2).
    return_details : bool
        Also return a dict with ``symprec``, ``number``, ``symbol`` (layer or
        space group), ``n_basis`` (particles per primitive cell) and
        ``primitive_cell``.

    Returns
    -------
    str or (str, dict)
        2D: ``"hexagonal"``, ``"square"``, ``"rectangular"``, ``"diamond"`` or
        ``"parallelogram"``; 3D: Pearson symbol of the Bravais lattice.

    Raises
    ------
    LatticeNotFoundError
        (a ``ValueError``) when no tolerance finds at most ``max_basis``
        particles per primitive cell.
    """
    dim = _check_atoms(atoms, dim)
    if isinstance(max_basis, bool) or not isinstance(max_basis, numbers.Integral) or max_basis < 1:
        raise ValueError(f"max_basis must be an integer >= 1, got {max_basis!r}")
    cell, spacing = _spglib_cell(atoms, dim)
    if symprec is None:
        ladder = [f * spacing for f in SYMPREC_LADDER]
    else:
        if isinstance(symprec, bool) or not isinstance(symprec, numbers.Real) or not symprec > 0:
            raise ValueError(f"symprec must be a number > 0 or None, got {symprec!r}")
        ladder = [float(symprec)]
    n = len(atoms)
    tried = []
    found = []  # (order of the lattice point group, tol, name, details) at every accepted rung
    for i, tol in enumerate(ladder):
        if found and tol > max(found[0][1], classify_up_to * spacing):
            break
        data = _dataset(cell, dim, tol)
        if data is None:
            tried.append((tol, None))
            continue
        n_trans = int(sum(np.array_equal(rot, np.eye(3, dtype=int)) for rot in data.rotations))
        n_basis = n // n_trans if n % n_trans == 0 else n
        tried.append((tol, n_basis))
        if n_basis <= max_basis:
            if dim == 2:
                name = layer_group_to_pattern(data.number, data.international)
            else:
                name = space_group_to_bravais(data.number, data.international)
            info = dict(symprec=tol, number=data.number, symbol=data.international, n_basis=n_basis,
                        primitive_cell=np.asarray(data.primitive_lattice))
            found.append((_HOLOHEDRY_ORDER[name], tol, name, info))
    if found:
        # highest point symmetry among the accepted tolerances (the smallest tolerance on ties)
        _, _, name, info = max(found, key=lambda item: (item[0], -item[1]))
        return (name, info) if return_details else name
    summary = ", ".join(f"symprec={t:.2g}: " + ("spglib failed" if b is None else f"{b} per primitive cell")
                        for t, b in tried)
    raise LatticeNotFoundError(
        f"no lattice with at most {max_basis} particle(s) per primitive cell found among {n} particles "
        f"({summary}); the arrangement is not periodic within tolerance")


def classify_cell(cell_vv, dim=3, symprec=None):
    """Bravais lattice of a one-particle cell (rows); see :func:`classify_lattice`.

    ``symprec`` is relative to the spacing ``|det cell|**(1/dim)``; None climbs the ladder.
    """
    from ase import Atoms

    cell_vv = np.asarray(cell_vv, dtype=float)
    if dim == 2:
        full = np.eye(3)
        full[:2, :2] = cell_vv[:2, :2]
        atoms = Atoms("X", positions=[[0, 0, 0]], cell=full, pbc=(True, True, False))
    else:
        atoms = Atoms("X", positions=[[0, 0, 0]], cell=cell_vv, pbc=True)
    scale = abs(np.linalg.det(cell_vv[:dim, :dim])) ** (1.0 / dim)
    return classify_lattice(atoms, symprec=None if symprec is None else symprec * scale, dim=dim)


def pattern_name_3d(atoms, symprec=None):
    """``"sc"``, ``"bcc"``, ``"fcc"``, ``"hcp"`` or the Bravais symbol of a 3D arrangement.

    ``hcp`` is space group 194 (P6_3/mmc) with two particles per primitive cell.
    """
    name, info = classify_lattice(atoms, symprec=symprec, dim=3, max_basis=2, return_details=True)
    if info["n_basis"] == 1:
        return CUBIC_NAMES.get(name, name)
    if info["number"] == 194:
        return "hcp"
    return f"{name} ({info['n_basis']}-particle basis, {info['symbol']})"
