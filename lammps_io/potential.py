"""Fan's interior total error as a LAMMPS pair potential.

Fan Eq. 3.8 without boundary term,

    E = sum_{i,j incl. i = j} W(r_ij, h) v0 vt - V,

counts each unordered pair twice, so as a pair potential (each pair once)

    phi(r) = 2 v0 vt W(r, h),     W = sigma_d / h^d f(r / h),

with h the kernel support (the LAMMPS cut-off).  The self term
``N v0 vt W(0, h) - V`` is a constant LAMMPS does not know: add
:func:`fan_self_energy` to LAMMPS' potential energy to get Fan's E.
The default v0 = vt = dx^d (Fan Eq. 3.3).

Two LAMMPS forms are provided: ``pair_style lepton`` with the exact
polynomial (forces by symbolic differentiation) and ``pair_style table``
written by :func:`fan_pair_table` (spline interpolation; LAMMPS re-tabulates evenly in r^2, so close pairs need many points:
20000 give ~1e-10 relative forces on random sets, 2000 only ~1e-5 in 3D).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ase_sphrelax.kernels import get_kernel

__all__ = [
    "fan_pair_prefactor",
    "fan_pair_energy",
    "fan_self_energy",
    "lepton_expression",
    "fan_pair_table",
    "pair_commands",
    "PAIR_STYLES",
]

PAIR_STYLES = ("lepton", "table")


def _check(h, dx, dim):
    if not (np.isscalar(h) and np.isfinite(h) and h > 0):
        raise ValueError(f"h (kernel support radius) must be a positive float, got {h!r}")
    if not (np.isscalar(dx) and np.isfinite(dx) and dx > 0):
        raise ValueError(f"dx (particle spacing) must be a positive float, got {dx!r}")
    if dim not in (1, 2, 3):
        raise ValueError(f"dim must be 1, 2 or 3, got {dim!r}")


def _volumes(dx, dim, v0, vt):
    v0 = dx**dim if v0 is None else float(v0)
    vt = v0 if vt is None else float(vt)
    return v0, vt


def fan_pair_prefactor(h, dx, dim, kernel="wendland_c2", v0=None, vt=None):
    """C with phi(r) = C f(r/h): C = 2 v0 vt sigma_d / h^d."""
    _check(h, dx, dim)
    k = get_kernel(kernel, dim)
    v0, vt = _volumes(dx, dim, v0, vt)
    return 2.0 * v0 * vt * k.sigma / h**dim


def fan_pair_energy(r, h, dx, dim, kernel="wendland_c2", v0=None, vt=None):
    """phi(r) = 2 v0 vt W(r, h) and dphi/dr (arrays)."""
    _check(h, dx, dim)
    k = get_kernel(kernel, dim)
    v0, vt = _volumes(dx, dim, v0, vt)
    return 2.0 * v0 * vt * k.w(r, h), 2.0 * v0 * vt * k.dw(r, h)


def fan_self_energy(n, h, dx, dim, volume, kernel="wendland_c2", v0=None, vt=None):
    """Constant ``N v0 vt W(0, h) - V`` missing from LAMMPS' pair energy (Fan Eq. 3.8)."""
    _check(h, dx, dim)
    k = get_kernel(kernel, dim)
    v0, vt = _volumes(dx, dim, v0, vt)
    return float(n * v0 * vt * k.w0(h) - volume)


def _profile_horner(kernel_obj, var="u"):
    """Horner string of the single-segment profile in ``u = breaks[1] - q``
    (the convention of :func:`ase_sphrelax.kernels.profile_value_and_slope`)."""
    coef = kernel_obj.coef[0]
    horner = f"{coef[-1]:.17g}"
    for a in coef[-2::-1]:
        horner = f"{a:.17g}+{var}*({horner})"
    return horner


def lepton_expression(h, dx, dim, kernel="wendland_c2", v0=None, vt=None):
    """Lepton expression of phi(r) = C f(r/h) (Horner form in u = 1 - r/h, no cancellation near r = h).

    Only single-segment profiles (Wendland kernels) can be written this way;
    use the table style for piecewise kernels.  The polynomial is checked
    against ``Kernel.profile`` so a change of the kernel representation cannot
    go unnoticed.
    """
    k = get_kernel(kernel, dim)
    if k.coef.shape[0] != 1:
        raise ValueError(f"pair_style lepton needs a single-polynomial kernel, {kernel!r} is piecewise: use style='table'")
    right = float(k.breaks[1])
    q = np.linspace(0.0, 0.999, 37)
    u = right - q
    mine = np.polynomial.polynomial.polyval(u, k.coef[0])
    if not np.allclose(mine, k.profile(q), rtol=1e-12, atol=1e-14):
        raise RuntimeError("kernel coefficients are not in powers of u = breaks[1] - q; update lammps_io.potential")
    c = fan_pair_prefactor(h, dx, dim, kernel, v0, vt)
    return f"C*({_profile_horner(k)});u={right:.17g}-r/H;C={c:.17g};H={h:.17g}"


def fan_pair_table(h, dx, dim, n=2000, path="fan_pair.table", keyword="FAN", kernel="wendland_c2",
                   rmin=None, v0=None, vt=None):
    """Write phi(r) and -dphi/dr as a ``pair_style table`` file.

    Parameters
    ----------
    h, dx : float
        Kernel support and particle spacing (v0 = vt = dx^dim by default).
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
    _check(h, dx, dim)
    if not (isinstance(n, (int, np.integer)) and n >= 2):
        raise ValueError(f"n (table points) must be an integer >= 2, got {n!r}")
    rmin = 1e-3 * h if rmin is None else float(rmin)
    if not 0 < rmin < h:
        raise ValueError(f"rmin must lie in (0, h), got {rmin!r}")
    r = np.linspace(rmin, h, n)
    e, de = fan_pair_energy(r, h, dx, dim, kernel, v0, vt)
    e[-1] = 0.0
    de[-1] = 0.0
    lines = [f"# Fan et al. pair potential phi(r) = 2 v0 vt W(r, h), kernel {kernel}, dim {dim}, h {h!r}, dx {dx!r}",
             "", keyword, f"N {n} R {rmin:.17g} {h:.17g}", ""]
    lines += [f"{i + 1} {ri:.17g} {ei:.17g} {-dei:.17g}" for i, (ri, ei, dei) in enumerate(zip(r, e, de))]
    path = Path(path)
    path.write_text("\n".join(lines) + "\n")
    return path, keyword


def pair_commands(h, dx, dim, style="lepton", kernel="wendland_c2", table_path=None, n_table=20000,
                  v0=None, vt=None):
    """LAMMPS commands defining phi for all type pairs (cut-off h)."""
    if style not in PAIR_STYLES:
        raise ValueError(f"style must be one of {PAIR_STYLES}, got {style!r}")
    if style == "lepton":
        expr = lepton_expression(h, dx, dim, kernel, v0, vt)
        return [f"pair_style lepton {h:.17g}", f'pair_coeff * * "{expr}"']
    if table_path is None:
        raise ValueError("table_path is required for style='table'")
    path, keyword = fan_pair_table(h, dx, dim, n=n_table, path=table_path, kernel=kernel, v0=v0, vt=vt)
    return [f"pair_style table spline {n_table}", f"pair_coeff * * {Path(path).resolve()} {keyword} {h:.17g}"]
