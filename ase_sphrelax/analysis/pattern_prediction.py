"""Predicted lattice patterns: the largest characteristic volume over each family (Fan Tables 1-2, App. B).

The predicted pattern (Table 1) is the family whose best member has the
largest ``v_c`` (:mod:`~ase_sphrelax.analysis.lattice_sums`, Eq. 5.2); the
cells are those of :mod:`~ase_sphrelax.analysis.pattern_cells`. Everything is
at unit particle volume (``dx = 1``), so ``h`` is Fan's ``h / dx``.

Parameter ranges in 2D
----------------------
The lattice is always scaled to unit area per particle. Two conventions:

``convention="fan"`` (default) -- the parameter ranges recovered from Table 2.
    Every aspect ratio starts one step of 0.005 above its degenerate value,
    which reproduces all of Table 2's hexagonal, square, rectangular and
    parallelogram columns and its Pattern column (with the printed ``k, r``):

    * ``"hexagonal"``, ``"square"``: unique lattices, no parameters.
    * ``"rectangular"`` (Eq. B.1): ``a1 = (a, 0)``, ``a2 = (0, k a)``,
      ``k a**2 = 1``, ``k`` in ``[1.005, 4]`` (``k = 1`` is the square; the
      column equals the square one to the printed digits wherever the square
      wins).
    * ``"diamond"`` (centred rectangular, Fig. 7 right): conventional
      rectangle ``A x k A`` with a particle at its centre, ``k A**2 / 2 = 1``,
      ``k`` in ``[2.01, 8]``; primitive vectors ``(A, 0)``, ``(A/2, k A/2)``.
      The lower bound excludes the square (``k = 1``) and the hexagonal
      (``k = sqrt 3``) special cases: this is why Table 2's diamond column is
      *below* the hexagonal one for ``h <= 1.8`` (0.872 at 1.5 is the
      ``k = 2.01`` boundary lattice) and below the square one for 1.85-2.05.
    * ``"parallelogram"`` (oblique, Fig. 8): base ``s`` along x, height
      ``H``, ``k = H / s`` in ``[1.005, 4]``, slant ``r`` = offset / height,
      ``a1 = (s, 0)``, ``a2 = (r H, H)``, ``s H = 1``. ``r`` and ``1/k - r``
      are mirror images; ``r`` is reported in ``[0, 1/(2k)]`` (the paper
      prints either branch, e.g. 0.86 for our 0.14 at h = 2.8). The
      hexagonal lattice needs ``k <= sqrt(3)/2`` and is excluded; every
      rectangular (``r = 0``) and diamond (``r = 1/(2k)``) candidate of the
      ranges above is also a parallelogram candidate.

    The predicted pattern (Table 1) is the family with the largest ``v_c``;
    since the parallelogram family contains the rectangular and diamond
    ones, ties go to ``"parallelogram"``, so the winner is always one of the
    three patterns of Table 1 (hexagonal, square, parallelogram).

``convention="bravais"`` -- the closed Bravais families.
    ``"rectangular"`` has ``k >= 1`` (contains the square), ``"diamond"`` has
    ``k >= 1`` (contains the square at ``k = 1`` and the hexagonal lattice at
    ``k = sqrt 3``), and ``"parallelogram"`` is every lattice (``k >= sqrt(3)/2``).
    The predicted pattern is the most symmetric family that attains the
    global maximum (within ``1e-9`` relative), i.e. the symmetry class of the
    lattice a relaxation finds and :func:`~ase_sphrelax.analysis.symmetry.classify_lattice`
    reports. It differs from Table 1: the optimum at h = 2.1-2.2, 2.8-3.0 and
    3.1-3.25 is a centred rectangular ("diamond") lattice (the paper's
    parallelogram ``k = 1.18, r = 0.42`` has ``r = 1/(2k)``, i.e. it *is*
    centred; at 2.8-3.0 the paper's ``k = 1.0`` is the boundary of its
    range, the unconstrained optimum being a rhombic lattice with ``k ~ 0.98``
    in parallelogram units), and only at 3.05 is the optimum truly oblique
    (by ``2e-7`` in ``v_c``).

3D patterns
-----------
``"sc"``, ``"bcc"``, ``"fcc"``, ``"hcp"`` (ideal ``c/a = sqrt(8/3)``) and
``"general"``: the best one-atom lattice over all cell shapes of unit volume
(five free parameters, multi-start Nelder-Mead).
"""
from __future__ import annotations

import math

import numpy as np
from scipy.optimize import minimize, minimize_scalar

from ..checks import check_dim, check_positive
from ..kernels import get_kernel
from .lattice_sums import characteristic_volume_of_cell, lattice_kernel_sum
from .pattern_cells import _HCP_C_OVER_A, _SQRT3, PATTERNS_2D, PATTERNS_3D, _cell_2d, _cell_3d, _check_pattern

__all__ = ["CONVENTIONS", "characteristic_volume", "predict_pattern", "pattern_table"]

CONVENTIONS = ("fan", "bravais")

# recovered lower bounds of the aspect ratios (see module docstring)
_FAN_K_MIN = 1.005
_K_MAX = 4.0
_TIE_RTOL = 1e-9


def _check_convention(convention):
    if convention not in CONVENTIONS:
        raise ValueError(f"convention must be one of {CONVENTIONS}, got {convention!r}")
    return convention



# -- optimisation of the free parameters ----------------------------------------------------
def _maximise_1d(fun, lo, hi, n_grid=121):
    """Global max of a smooth 1D function on [lo, hi]: grid, then bounded Brent around the best node."""
    xs = np.linspace(lo, hi, n_grid)
    vs = np.array([fun(x) for x in xs])
    best = []
    # refine around every local maximum of the grid (incl. end points)
    for i in range(n_grid):
        if (i == 0 or vs[i] >= vs[i - 1]) and (i == n_grid - 1 or vs[i] >= vs[i + 1]):
            a, b = xs[max(i - 1, 0)], xs[min(i + 1, n_grid - 1)]
            res = minimize_scalar(lambda x: -fun(x), bounds=(a, b), method="bounded",
                                  options=dict(xatol=1e-11))
            best.append((vs[i], xs[i]))
            best.append((-res.fun, float(res.x)))
    return max(best)


def _maximise_2d(fun, k_lo, k_hi, r_hi_of_k, n_k=41, n_r=21, n_refine=6):
    """Global max of fun(k, r) on {k_lo <= k <= k_hi, 0 <= r <= r_hi(k)}.

    Coarse grid, then Nelder-Mead (on a clipped parameterisation) from the best
    grid nodes, then a 1D refinement along each boundary (k = k_lo, r = 0,
    r = r_hi(k)) because the constrained optimum often sits there.
    """
    def clip(k, r):
        k = min(max(k, k_lo), k_hi)
        return k, min(max(r, 0.0), r_hi_of_k(k))

    nodes = []
    for k in np.linspace(k_lo, k_hi, n_k):
        for r in np.linspace(0.0, r_hi_of_k(k), n_r):
            nodes.append((fun(k, r), k, r))
    nodes.sort(reverse=True)
    cands = [nodes[0]]
    for _, k0, r0 in nodes[:n_refine]:
        res = minimize(lambda p: -fun(*clip(*p)), [k0, r0], method="Nelder-Mead",
                       options=dict(xatol=1e-10, fatol=1e-15, maxiter=4000,
                                    initial_simplex=[[k0, r0], [k0 + 0.02, r0], [k0, r0 + 0.02]]))
        k, r = clip(*res.x)
        cands.append((fun(k, r), k, r))
    # boundaries
    v, r = _maximise_1d(lambda r: fun(k_lo, r), 0.0, r_hi_of_k(k_lo))
    cands.append((v, k_lo, r))
    v, k = _maximise_1d(lambda k: fun(k, 0.0), k_lo, k_hi)
    cands.append((v, k, 0.0))
    v, k = _maximise_1d(lambda k: fun(k, r_hi_of_k(k)), k_lo, k_hi)
    cands.append((v, k, r_hi_of_k(k)))
    return max(cands)


def _vc_2d(pattern, h, kernel, **params):
    return 1.0 / lattice_kernel_sum(_cell_2d(pattern, params), h, kernel)


def _characteristic_volume_2d(pattern, h, kernel, convention):
    if pattern in ("hexagonal", "square"):
        return _vc_2d(pattern, h, kernel), {}
    k_lo = _FAN_K_MIN if convention == "fan" else 1.0
    if pattern == "rectangular":
        v, k = _maximise_1d(lambda k: _vc_2d("rectangular", h, kernel, k=k), k_lo, _K_MAX)
        return v, {"k": k, "a": 1.0 / math.sqrt(k)}
    if pattern == "diamond":
        d_lo = 2.0 * _FAN_K_MIN if convention == "fan" else 1.0
        v, k = _maximise_1d(lambda k: _vc_2d("diamond", h, kernel, k=k), d_lo, 2.0 * _K_MAX, n_grid=241)
        return v, {"k": k, "a": math.sqrt(2.0 / k)}
    # parallelogram: k = H/s, r = offset/H in [0, 1/(2k)] (mirror symmetry r <-> 1/k - r)
    if convention == "bravais":
        k_lo = 0.5 * _SQRT3  # the hexagonal lattice has the largest shortest vector
    v, k, r = _maximise_2d(lambda k, r: _vc_2d("parallelogram", h, kernel, k=k, r=r),
                           k_lo, _K_MAX, lambda k: 0.5 / k)
    return v, {"k": k, "r": r, "a": math.sqrt(k)}


# -- 3D ---------------------------------------------------------------------------------
def _tri_cell(p):
    """Lower-triangular unit-volume cell from 5 parameters (log diag x2, 3 off-diagonals)."""
    l11, l22 = math.exp(p[0]), math.exp(p[1])
    l33 = 1.0 / (l11 * l22)
    return np.array([[l11, 0.0, 0.0], [p[2], l22, 0.0], [p[3], p[4], l33]])


def _reduce_cell(cell):
    """Niggli-reduced cell (ase) as rows, same lattice."""
    from ase.geometry.minkowski_reduction import minkowski_reduce
    red, _ = minkowski_reduce(cell)
    return np.asarray(red, dtype=float)


def _to_tri_params(cell):
    """5 parameters of the lower-triangular cell with the same metric as ``cell`` (rows)."""
    cell = cell * abs(np.linalg.det(cell)) ** (-1.0 / 3.0)
    g = cell @ cell.T
    lower = np.linalg.cholesky(g)
    lower *= np.linalg.det(lower) ** (-1.0 / 3.0)
    return np.array([math.log(lower[0, 0]), math.log(lower[1, 1]), lower[1, 0], lower[2, 0], lower[2, 1]])


def _general_3d(h, kernel, n_starts=6, seed=0):
    """Best one-atom lattice of unit volume: multi-start Nelder-Mead over 5 cell parameters.

    Starts: sc, bcc, fcc, simple hexagonal and random cells; each run is
    restarted once from a Minkowski-reduced cell to escape skewed bases.
    """
    rng = np.random.default_rng(seed)

    def neg(p):
        return -1.0 / lattice_kernel_sum(_tri_cell(p), h, kernel)

    starts = [_to_tri_params(_cell_3d(name)[0]) for name in ("sc", "bcc", "fcc")]
    starts.append(_to_tri_params(np.array([[1.0, 0, 0], [-0.5, 0.5 * _SQRT3, 0], [0, 0, 1.0]])))
    while len(starts) < n_starts:
        starts.append(rng.normal(0.0, 0.3, 5))
    best = None
    for p0 in starts:
        p = p0 + rng.normal(0.0, 0.02, 5)
        for _ in range(2):
            res = minimize(neg, p, method="Nelder-Mead",
                           options=dict(xatol=1e-8, fatol=1e-14, maxiter=3000, adaptive=True))
            p = _to_tri_params(_reduce_cell(_tri_cell(res.x)))
        if best is None or res.fun < best.fun:
            best = res
    cell = _reduce_cell(_tri_cell(best.x))
    return -best.fun, {"cell": cell}


def _characteristic_volume_3d(pattern, h, kernel):
    if pattern == "general":
        return _general_3d(h, kernel)
    cell, basis = _cell_3d(pattern)
    v = characteristic_volume_of_cell(cell, h, kernel, basis)
    return v, ({"c_over_a": _HCP_C_OVER_A} if pattern == "hcp" else {})



# -- public API ---------------------------------------------------------------------------
def characteristic_volume(pattern, h_over_dx, dim=2, kernel="wendland_c2", convention="fan"):
    """Largest characteristic volume of a pattern over its free parameters (Eq. 5.2, B.1).

    Parameters
    ----------
    pattern : str
        2D: ``"hexagonal"``, ``"square"``, ``"rectangular"``, ``"diamond"``,
        ``"parallelogram"``; 3D: ``"sc"``, ``"bcc"``, ``"fcc"``, ``"hcp"``,
        ``"general"``.
    h_over_dx : float
        Kernel support radius in units of ``dx`` (unit particle volume).
    dim : {2, 3}
    kernel : str
        Kernel name; Fan uses ``"wendland_c2"``.
    convention : {"fan", "bravais"}
        2D parameter ranges (see the module docstring): ``"fan"`` reproduces
        Table 2, ``"bravais"`` uses the closed Bravais families.

    Returns
    -------
    v_c : float
        ``max 1 / sum_j W(|r_j|, h)`` at unit particle volume.
    params : dict
        The maximiser: 2D ``k`` (and ``r`` for parallelograms, ``a`` = the
        shorter edge/axis or the height); 3D ``cell`` (rows) for ``"general"``,
        ``c_over_a`` for ``"hcp"``.
    """
    dim = check_dim(dim, allowed=(2, 3))
    _check_pattern(pattern, dim)
    h = check_positive("h_over_dx", h_over_dx)
    _check_convention(convention)
    get_kernel(kernel, dim)  # validates the name
    if dim == 2:
        return _characteristic_volume_2d(pattern, h, kernel, convention)
    return _characteristic_volume_3d(pattern, h, kernel)


def _winner_2d(values, convention):
    best = max(v for v, _ in values.values())
    tol = _TIE_RTOL * best
    if convention == "fan":
        # parallelogram contains rectangular and diamond: ties go to it; hexagonal/square are outside it
        order = ("hexagonal", "square", "parallelogram", "diamond", "rectangular")
    else:
        order = ("hexagonal", "square", "rectangular", "diamond", "parallelogram")
    for name in order:
        if values[name][0] >= best - tol:
            return name
    raise AssertionError("unreachable")


def _winner_3d(values):
    best_named = max(("sc", "bcc", "fcc", "hcp"), key=lambda n: values[n][0])
    v_gen, p_gen = values["general"]
    if v_gen <= values[best_named][0] * (1.0 + 1e-7):
        return best_named
    from .symmetry import classify_cell
    return classify_cell(p_gen["cell"], dim=3)


def predict_pattern(h_over_dx, dim=2, kernel="wendland_c2", convention="fan", return_values=False):
    """Pattern with the largest characteristic volume (Fan Table 1 from first principles).

    Parameters
    ----------
    h_over_dx : float
    dim : {2, 3}
    kernel : str
    convention : {"fan", "bravais"}
        2D only. ``"fan"`` reproduces Tables 1-2 (``"hexagonal"``, ``"square"``
        or ``"parallelogram"``); ``"bravais"`` names the symmetry class of the
        global maximiser, which is what a relaxation plus
        :func:`~ase_sphrelax.analysis.symmetry.classify_lattice` gives.
    return_values : bool
        Also return ``{pattern: (v_c, params)}``.

    Returns
    -------
    str or (str, dict)
        3D: ``"sc"``, ``"bcc"``, ``"fcc"`` or ``"hcp"`` unless the best general
        one-atom lattice beats them by more than ``1e-7`` relative, then its
        Bravais symbol (e.g. ``"tI"``).
    """
    dim = check_dim(dim, allowed=(2, 3))
    _check_convention(convention)
    names = PATTERNS_2D if dim == 2 else PATTERNS_3D
    values = {n: characteristic_volume(n, h_over_dx, dim, kernel, convention) for n in names}
    winner = _winner_2d(values, convention) if dim == 2 else _winner_3d(values)
    return (winner, values) if return_values else winner


def pattern_table(h_values=None, dim=2, kernel="wendland_c2", progress=False):
    """Rows of Table 2 (2D, both conventions) or its 3D analogue.

    ``progress``: a tqdm bar over the rows (None: only on a terminal; 3D takes about 20 s).

    Returns
    -------
    list of dict
        2D keys: ``h``, ``v_<pattern>`` (Fan convention), ``pattern``, ``k``,
        ``r`` (winner's parameters), ``v_best`` (global maximum),
        ``pattern_bravais``, ``k_bravais``, ``r_bravais``.
        3D keys: ``h``, ``v_<pattern>``, ``pattern``, ``bravais_general`` (Pearson
        symbol of the best one-atom lattice), ``cell_general``.
    """
    dim = check_dim(dim, allowed=(2, 3))
    if h_values is None:
        h_values = np.round(np.arange(1.5, 3.5 + 1e-9, 0.05), 2)
    rows = []
    if progress is not False:
        from tqdm.auto import tqdm

        h_values = tqdm(h_values, desc=f"Table 2 ({dim}D)", unit="row", disable=None if progress is None else False,
                        mininterval=0.5)
    for h in h_values:
        h = float(h)
        row = {"h": h}
        if dim == 2:
            winner, values = predict_pattern(h, 2, kernel, "fan", return_values=True)
            for name in PATTERNS_2D:
                row[f"v_{name}"] = values[name][0]
            params = values[winner][1]
            row.update(pattern=winner, k=params.get("k", np.nan), r=params.get("r", np.nan))
            winner_b, values_b = predict_pattern(h, 2, kernel, "bravais", return_values=True)
            pb = values_b[winner_b][1]
            row.update(v_best=values_b["parallelogram"][0], pattern_bravais=winner_b,
                       k_bravais=pb.get("k", np.nan), r_bravais=pb.get("r", np.nan))
        else:
            winner, values = predict_pattern(h, 3, kernel, return_values=True)
            for name in PATTERNS_3D:
                row[f"v_{name}"] = values[name][0]
            from .symmetry import classify_cell

            row.update(pattern=winner, bravais_general=classify_cell(values["general"][1]["cell"]),
                       cell_general=values["general"][1]["cell"])
        rows.append(row)
    return rows

