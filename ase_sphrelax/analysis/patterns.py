"""Relaxed periodic patterns: variable-cell relaxation at constant area/volume (Fan Sec. 5.1).

:func:`relax_lattice` minimises Fan's total error (Eq. 3.8, periodic interior
case, ``v0 = vt = V / N``) over particle positions *and* cell shape at fixed
area (2D) or volume (3D), from several starts, with an ASE optimiser on
:class:`~ase_sphrelax.analysis.cell_filter.ConstantMeasureCellFilter`. At unit
particle volume ``E = sum_i sum_j W_ij - N``, so Eq. 5.2 gives the
characteristic volume of the result: ``v_c = 1 / (E / N + 1)``.

:func:`lattice_report` and :func:`write_table` are the bodies of the CLI
commands ``sphrelax lattice`` and ``sphrelax table``.
"""
from __future__ import annotations

import csv
import math
import numbers

import numpy as np
from ase import Atoms

from ..checks import check_dim, check_positive
from ..drivers.optimizers import OPTIMIZERS
from .cell_filter import ConstantMeasureCellFilter
from .pattern_cells import PATTERNS_2D, PATTERNS_3D, pattern_cell
from .pattern_prediction import characteristic_volume, pattern_table, predict_pattern

__all__ = ["relax_lattice", "lattice_supercell", "random_start", "lattice_report", "write_table", "table_path",
           "TABLE_NAME"]

#: the one file name of Table 2 (2D) and its 3D analogue, for ``sphrelax table`` and the examples
TABLE_NAME = "table2_{dim}d.csv"


def table_path(dim, folder="."):
    """``folder / table2_<dim>d.csv``, the CSV of :func:`write_table` (the PNG goes beside it)."""
    from pathlib import Path

    return Path(folder) / TABLE_NAME.format(dim=dim)


def _bar(iterable, total, label, progress):
    """``iterable`` wrapped in a tqdm bar when ``progress`` (None: only on a terminal)."""
    if progress is False:
        return iterable
    from tqdm.auto import tqdm

    return tqdm(iterable, total=total, desc=label, unit="start" if "relax" in label else "row",
                disable=None if progress is None else False, mininterval=0.5)


def _factor_near_square(n, dim):
    """Repetitions (n_1, ..., n_dim) with product n, as equal as possible."""
    best = None
    if dim == 2:
        for a in range(1, n + 1):
            if n % a == 0:
                reps = (a, n // a)
                score = max(reps) / min(reps)
                if best is None or score < best[0]:
                    best = (score, reps)
    else:
        for a in range(1, n + 1):
            if n % a:
                continue
            for b in range(1, n // a + 1):
                if (n // a) % b == 0:
                    reps = (a, b, n // a // b)
                    score = max(reps) / min(reps)
                    if best is None or score < best[0]:
                        best = (score, reps)
    return best[1]


def _embed(cell_vv, basis_bv, dim):
    if dim == 2:
        full = np.eye(3)
        full[:2, :2] = cell_vv
        pos = np.zeros((len(basis_bv), 3))
        pos[:, :2] = basis_bv
        return Atoms(f"X{len(basis_bv)}", positions=pos, cell=full, pbc=(True, True, False))
    return Atoms(f"X{len(basis_bv)}", positions=basis_bv, cell=cell_vv, pbc=True)


def lattice_supercell(pattern, n_atoms, params=None, dim=2):
    """``n_atoms`` particles on a pattern (unit particle volume), as near-square repetitions.

    Returns None when ``n_atoms`` is not a multiple of the pattern's basis (hcp: 2).
    """
    cell, basis = pattern_cell(pattern, params, dim)
    nb = len(basis)
    if n_atoms % nb:
        return None
    atoms = _embed(cell, basis, dim)
    reps = _factor_near_square(n_atoms // nb, dim)
    return atoms.repeat(reps + (1,) if dim == 2 else reps)


def random_start(n_atoms, dim=2, rng=None, shear=0.2):
    """Uniform random positions in a randomly sheared cell of unit particle volume."""
    from .cell_filter import sym_expm, traceless_symmetric_basis

    rng = np.random.default_rng(rng)
    side = n_atoms ** (1.0 / dim)
    x = sum(c * b for c, b in zip(rng.normal(0.0, shear, 2 if dim == 2 else 5), traceless_symmetric_basis(dim)))
    f = sym_expm(x)[:dim, :dim]
    cell = side * f.T
    pos = rng.random((n_atoms, dim)) @ cell
    return _embed(cell, pos, dim)


def _check_int(name, value, minimum):
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)


def _relax_one(atoms, h, dim, kernel, optimizer, fmax, steps):
    from ..calculators.fan import FanCalculator
    from ..drivers.optimizers import make_optimizer

    atoms = atoms.copy()
    atoms.calc = FanCalculator(h=h, dx=None, dim=dim, kernel=kernel)
    filt = ConstantMeasureCellFilter(atoms, dim=dim)
    opt = make_optimizer(optimizer, filt, h=h, logfile=None)
    converged = bool(opt.run(fmax=fmax, steps=steps))
    energy = atoms.get_potential_energy()
    n = len(atoms)
    atoms.wrap()
    out = atoms.copy()
    out.calc = None
    out.info.update(energy=energy, v_c=1.0 / (energy / n + 1.0), converged=converged, steps=opt.nsteps)
    return out


def relax_lattice(h_over_dx, n_atoms, dim=2, optimizer="fire", seed=None, n_starts=4, lattice_starts=True,
                  noise=0.05, fmax=1e-6, steps=4000, kernel="wendland_c2", return_all=False, progress=False):
    """Relax ``n_atoms`` periodic particles in position and cell shape; return the lowest-E result.

    Parameters
    ----------
    h_over_dx : float
        Kernel support radius in units of ``dx = (V/N)**(1/d)``; the cell has
        unit particle volume throughout (constant area / volume).
    n_atoms : int
    dim : {2, 3}
    optimizer : one of :data:`ase_sphrelax.drivers.optimizers.OPTIMIZERS`
        Built by :func:`ase_sphrelax.drivers.make_optimizer` on the filter.
        ``"fan"`` (Eq. 2.4, fixed step ``c h``) oscillates at the step scale
        and does not reach a tight ``fmax``; ``"fire"`` is the tested choice
        (``"bfgs"`` is slow here: scipy/LAPACK calls on tiny matrices cost ms).
    seed : int, optional
        Seed of the random starts.
    n_starts : int
        Random starts: uniform random positions in a randomly sheared cell.
    lattice_starts : bool
        Also start from each candidate pattern at its optimal parameters
        (2D: the five families of Table 2, Bravais ranges; 3D: sc, bcc, fcc,
        hcp and the best one-atom lattice) as an ``n_atoms`` supercell when it
        fits, every particle displaced by ``noise`` (Gaussian, units of dx).
    fmax : float
        Convergence on the filter's generalised forces.
    steps : int
        Maximum optimiser steps per start.
    return_all : bool
        Also return the list of all relaxed starts.
    progress : bool or None
        A tqdm bar over the starts (None: only on a terminal).

    Returns
    -------
    ase.Atoms
        Lowest-energy result, without calculator; ``info`` holds ``energy``
        (Eq. 3.8), ``v_c = 1 / (E/N + 1)`` (Eq. 5.2), ``converged``,
        ``steps`` and ``start`` (which start produced it).
    """
    h = check_positive("h_over_dx", h_over_dx)
    dim = check_dim(dim, allowed=(2, 3))
    n_atoms = _check_int("n_atoms", n_atoms, 1)
    n_starts = _check_int("n_starts", n_starts, 0)
    if optimizer not in OPTIMIZERS:
        raise ValueError(f"optimizer must be one of {OPTIMIZERS}, got {optimizer!r}")
    if not (fmax > 0):
        raise ValueError(f"fmax must be > 0, got {fmax!r}")
    if n_starts == 0 and not lattice_starts:
        raise ValueError("need n_starts >= 1 or lattice_starts=True")
    rng = np.random.default_rng(seed)
    starts = []
    if lattice_starts:
        names = PATTERNS_2D if dim == 2 else PATTERNS_3D
        for name in names:
            params = characteristic_volume(name, h, dim, kernel, "bravais")[1] if dim == 2 else \
                characteristic_volume(name, h, dim, kernel)[1]
            atoms = lattice_supercell(name, n_atoms, params, dim)
            if atoms is None:
                continue
            atoms.positions[:, :dim] += rng.normal(0.0, noise, (n_atoms, dim))
            starts.append((f"lattice:{name}", atoms))
    for i in range(n_starts):
        starts.append((f"random:{i}", random_start(n_atoms, dim, rng)))
    results = []
    for label, atoms in _bar(starts, len(starts), f"relax {len(starts)} starts", progress):
        out = _relax_one(atoms, h, dim, kernel, optimizer, fmax, steps)
        out.info["start"] = label
        results.append(out)
    best = min(results, key=lambda a: a.info["energy"])
    return (best, results) if return_all else best


# -- CLI bodies -----------------------------------------------------------------------------
def lattice_report(h_over_dx, dim=2, n_atoms=None, seed=0, n_starts=2, progress=False):
    """Text for ``sphrelax lattice --h-over-dx H [--dim 3]``.

    Prints the predicted pattern (Fan's Table 1 convention and the symmetry of
    the optimum), ``v_c`` of every pattern with its parameters, and the
    pattern of a variable-cell relaxation identified by spglib (or that spglib
    found none: a line of the report, not an error). ``progress``: a bar over the
    relaxation starts (None: only on a terminal).
    """
    from .symmetry import LatticeNotFoundError, classify_lattice, pattern_name_3d

    lines = [f"h/dx = {h_over_dx:g}, dim = {dim}, kernel wendland_c2, unit particle volume"]
    if dim == 2:
        winner, values = predict_pattern(h_over_dx, 2, return_values=True)
        winner_b, values_b = predict_pattern(h_over_dx, 2, convention="bravais", return_values=True)
        lines.append(f"predicted pattern (Fan Table 1 convention): {winner}")
        lines.append(f"symmetry of the best lattice:               {winner_b}")
        lines.append(f"{'pattern':14s} {'v_c (Fan ranges)':>17s}  params            {'v_c (Bravais)':>14s}  params")
        for name in PATTERNS_2D:
            v, p = values[name]
            vb, pb = values_b[name]
            lines.append(f"{name:14s} {v:17.6f}  {_fmt(p):17s} {vb:14.6f}  {_fmt(pb)}")
        n_atoms = n_atoms or 16
    else:
        winner, values = predict_pattern(h_over_dx, 3, return_values=True)
        lines.append(f"predicted pattern: {winner}")
        for name in PATTERNS_3D:
            v, p = values[name]
            extra = ""
            if name == "general":
                from .symmetry import classify_cell

                extra = f"  Bravais {classify_cell(p['cell'])}"
            lines.append(f"{name:8s} {v:.6f}{extra}")
        n_atoms = n_atoms or 4
    relaxed = relax_lattice(h_over_dx, n_atoms, dim, seed=seed, n_starts=n_starts, progress=progress)
    try:
        label = classify_lattice(relaxed) if dim == 2 else pattern_name_3d(relaxed)
    except LatticeNotFoundError:
        label = "no periodic lattice identified by spglib (up to symprec 0.1)"
    lines.append(f"relaxed {n_atoms} particles (variable cell, constant {'area' if dim == 2 else 'volume'}): "
                 f"{label}, v_c = {relaxed.info['v_c']:.6f} (start {relaxed.info['start']})")
    return "\n".join(lines)


def _fmt(params):
    return " ".join(f"{k}={v:.3f}" for k, v in params.items() if k in ("k", "r", "c_over_a"))


def write_table(path_csv, path_png=None, dim=2, h_values=None, progress=False):
    """Write Table 2 (2D) or its 3D analogue as CSV, and a plot of v_c against h/dx per pattern.

    2D columns: ``h``, ``v_<pattern>`` for the five patterns (Fan ranges),
    ``pattern``, ``k``, ``r`` (Fan's Table 2), then ``v_best``,
    ``pattern_bravais``, ``k_bravais``, ``r_bravais`` (symmetry of the global
    optimum). 3D: ``v_sc, v_bcc, v_fcc, v_hcp, v_general``, ``pattern`` and the
    general cell. The plot shows ``v_c - v_hexagonal`` (2D) or ``v_c - v_fcc``
    (3D) so that the small differences are visible, with the winner marked.

    ``progress``: a tqdm bar over the rows (None: only on a terminal). The CLI and the
    examples name the file :func:`table_path` (``table2_<dim>d.csv``).

    Returns
    -------
    list of dict
        The rows written.
    """
    rows = pattern_table(h_values, dim, progress=progress)
    # Table 2's column order
    names = ("hexagonal", "square", "diamond", "rectangular", "parallelogram") if dim == 2 else PATTERNS_3D
    if dim == 2:
        fields = ["h"] + [f"v_{n}" for n in names] + ["pattern", "k", "r", "v_best", "pattern_bravais",
                                                       "k_bravais", "r_bravais"]
    else:
        fields = ["h"] + [f"v_{n}" for n in names] + ["pattern", "bravais_general", "cell_general"]
    with open(path_csv, "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(fields)
        for row in rows:
            out = []
            for f in fields:
                v = row[f]
                if isinstance(v, np.ndarray):
                    v = " ".join(f"{x:.6f}" for x in v.ravel())
                elif isinstance(v, float):
                    v = "" if math.isnan(v) else f"{v:.8f}" if f.startswith("v_") else f"{v:.4g}" if f == "h" else \
                        f"{v:.4f}"
                out.append(v)
            writer.writerow(out)
    if path_png:
        _plot_table(rows, names, dim, path_png)
    return rows


def _plot_table(rows, names, dim, path_png):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ref = "v_hexagonal" if dim == 2 else "v_fcc"
    h = np.array([r["h"] for r in rows])
    fig, (ax0, ax1) = plt.subplots(2, 1, figsize=(7.5, 8), sharex=True)
    markers = dict(zip(names, "os^vDx"))
    for name in names:
        v = np.array([r[f"v_{name}"] for r in rows])
        ax0.plot(h, v, marker=markers[name], ms=3, label=name)
        ax1.plot(h, v - np.array([r[ref] for r in rows]), marker=markers[name], ms=3, label=name)
    for r in rows:
        win = r["pattern"]
        key = f"v_{win}" if f"v_{win}" in r else "v_general"
        ax1.plot(r["h"], r[key] - r[ref], "k*", ms=9, zorder=5)
    ax1.plot([], [], "k*", ms=9, label="winner")
    # zoom on the competition near the top; far-off curves leave the panel
    gap = max(max(r[f"v_{n}"] for n in names) - r[ref] for r in rows)
    top = 1.25 * gap + 2e-4
    ax1.set_ylim(-1.6 * top, top)
    ax0.set_ylabel("$v_c$ (unit particle volume)")
    ax1.set_ylabel(f"$v_c - v_{{{ref[2:]}}}$ (zoom)")
    ax1.set_xlabel("$h/\\Delta x$")
    ax1.axhline(0.0, color="0.6", lw=0.5)
    ax1.legend(fontsize=8, ncol=2)
    title = "Fan et al. Table 2 (Wendland C2, 2D)" if dim == 2 else "3D lattices (Wendland C2)"
    ax0.set_title(title)
    fig.tight_layout()
    fig.savefig(path_png, dpi=130)
    plt.close(fig)
