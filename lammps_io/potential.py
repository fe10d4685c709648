"""Fan's pair part of the total error (Eq. 3.8) as a LAMMPS pair potential.

The model is :class:`ase_sphrelax.models.fan.FanModel`: Eq. 3.8 without boundary term,

    E = sum_{i,j incl. i = j} W(r_ij, h) v0 vt - V,

counts each unordered pair twice, so as a pair potential (each pair once)

    phi(r) = 2 v0 vt W(r, h) = C f(r / h),     C = FanModel.pair_prefactor(v0),

with h the kernel support (the LAMMPS cut-off). The self term ``N v0 vt W(0, h) - V``
(``FanModel.self_energy``) is a constant LAMMPS does not know: add :func:`fan_self_energy`
to LAMMPS' potential energy to get Fan's E. The default v0 = vt = dx^d (Fan Eq. 3.3).

This module only writes phi in LAMMPS' two forms: ``pair_style lepton`` with the exact
polynomial (forces by symbolic differentiation) and ``pair_style table`` written by
:func:`fan_pair_table` (spline interpolation; LAMMPS re-tabulates evenly in r^2, so close pairs need many points:
20000 give ~1e-10 relative forces on random sets, 2000 only ~1e-5 in 3D).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ase_sphrelax.checks import check_positive
from ase_sphrelax.kernels import get_kernel
from ase_sphrelax.models.fan import FanModel

__all__ = [
    "fan_self_energy",
    "lepton_expression",
    "fan_pair_table",
    "pair_commands",
    "check_pair_style",
    "check_table_points",
    "PAIR_STYLES",
]

PAIR_STYLES = ("lepton", "table")


def check_pair_style(style, kernel="wendland_c2", dim=2):
    """ValueError unless ``style`` is one of :data:`PAIR_STYLES` and can write ``kernel``.

    ``pair_style lepton`` takes one polynomial: piecewise kernels (cubic spline) need ``"table"``.
    """
    if style not in PAIR_STYLES:
        raise ValueError(f"style must be one of {PAIR_STYLES}, got {style!r}")
    k = get_kernel(kernel, dim)
    if style == "lepton" and k.coef.shape[0] != 1:
        raise ValueError(f"style='lepton' needs a single-polynomial kernel, {k.name!r} is piecewise: use style='table'")
    return style


def check_table_points(n, name="n_table"):
    """``n`` as an int >= 2 (points of a ``pair_style table`` file); ValueError naming ``name`` otherwise."""
    if isinstance(n, (bool, np.bool_)) or not isinstance(n, (int, np.integer)) or n < 2:
        raise ValueError(f"{name} (table points) must be an integer >= 2, got {n!r}")
    return int(n)


def _model_and_v0(h, dx, dim, kernel, v0):
    """The model of (h, dx, dim, kernel) and the particle volume: ``v0`` if given, else dx^dim."""
    model = FanModel(h, dx, dim=dim, kernel=kernel)
    if v0 is not None:
        return model, check_positive("v0", v0)
    if model.dx is None:
        raise ValueError("dx=None needs v0 (the particle volume v0 = vt); give dx or v0")
    return model, model.volumes(1).v0


def fan_self_energy(n, h, dx, dim, volume, kernel="wendland_c2", v0=None):
    """Constant ``N v0 vt W(0, h) - V`` missing from LAMMPS' pair energy (Fan Eq. 3.8)."""
    model, v0 = _model_and_v0(h, dx, dim, kernel, v0)
    return model.self_energy(n, v0, float(volume))


def _profile_horner(kernel_obj, var="u"):
    """Horner string of the single-segment profile in ``u = breaks[1] - q``
    (the convention of :func:`ase_sphrelax.kernels.profile_value_and_slope`)."""
    coef = kernel_obj.coef[0]
    horner = f"{coef[-1]:.17g}"
    for a in coef[-2::-1]:
        horner = f"{a:.17g}+{var}*({horner})"
    return horner


def lepton_expression(h, dx, dim, kernel="wendland_c2", v0=None):
    """Lepton expression of phi(r) = C f(r/h) (Horner form in u = 1 - r/h, no cancellation near r = h).

    Only single-segment profiles (Wendland kernels) can be written this way;
    use the table style for piecewise kernels.  The polynomial is checked
    against ``Kernel.profile`` so a change of the kernel representation cannot
    go unnoticed.
    """
    model, v0 = _model_and_v0(h, dx, dim, kernel, v0)
    check_pair_style("lepton", model.kernel, model.dim)
    k = model.kernel
    right = float(k.breaks[1])
    q = np.linspace(0.0, 0.999, 37)
    u = right - q
    mine = np.polynomial.polynomial.polyval(u, k.coef[0])
    if not np.allclose(mine, k.profile(q), rtol=1e-12, atol=1e-14):
        raise RuntimeError("kernel coefficients are not in powers of u = breaks[1] - q; update lammps_io.potential")
    c = model.pair_prefactor(v0)
    return f"C*({_profile_horner(k)});u={right:.17g}-r/H;C={c:.17g};H={model.h:.17g}"


def fan_pair_table(h, dx, dim, n=2000, path="fan_pair.table", keyword="FAN", kernel="wendland_c2",
                   rmin=None, v0=None):
    """Write phi(r) and -dphi/dr as a ``pair_style table`` file.

    Parameters
    ----------
    h, dx : float
        Kernel support and particle spacing (v0 = vt = dx^dim unless ``v0`` is given;
        dx may then be None).
    dim : {1, 2, 3}
    n : int
        Number of table points, equally spaced in r from ``rmin`` to ``h``
        (use ``pair_style table spline n``).
    path : str or Path
    keyword : str
        Section name for ``pair_coeff * * path keyword h``.
    rmin : float or None
        Inner end of the table (default 1e-3 h); LAMMPS stops if two
        particles come closer.

    Returns
    -------
    (Path, str)
        File path and keyword.
    """
    model, v0 = _model_and_v0(h, dx, dim, kernel, v0)
    h = model.h
    n = check_table_points(n, "n")
    rmin = 1e-3 * h if rmin is None else float(rmin)
    if not 0 < rmin < h:
        raise ValueError(f"rmin must lie in (0, h), got {rmin!r}")
    r = np.linspace(rmin, h, n)
    e, de = model.pair_energy(r, v0)
    e[-1] = 0.0
    de[-1] = 0.0
    lines = [f"# Fan et al. pair potential phi(r) = 2 v0 vt W(r, h), kernel {model.kernel.name}, dim {model.dim}, "
             f"h {h!r}, v0 = vt = {v0!r}",
             "", keyword, f"N {n} R {rmin:.17g} {h:.17g}", ""]
    lines += [f"{i + 1} {ri:.17g} {ei:.17g} {-dei:.17g}" for i, (ri, ei, dei) in enumerate(zip(r, e, de))]
    path = Path(path)
    path.write_text("\n".join(lines) + "\n")
    return path, keyword


def pair_commands(h, dx, dim, style="lepton", kernel="wendland_c2", table_path=None, n_table=20000, v0=None):
    """LAMMPS commands defining phi for all type pairs (cut-off h); ``v0`` as in :func:`fan_pair_table`."""
    check_pair_style(style, kernel, dim)
    if style == "lepton":
        expr = lepton_expression(h, dx, dim, kernel, v0)
        return [f"pair_style lepton {h:.17g}", f'pair_coeff * * "{expr}"']
    if table_path is None:
        raise ValueError("table_path is required for style='table'")
    path, keyword = fan_pair_table(h, dx, dim, n=n_table, path=table_path, kernel=kernel, v0=v0)
    return [f"pair_style table spline {n_table}", f"pair_coeff * * {Path(path).resolve()} {keyword} {h:.17g}"]
