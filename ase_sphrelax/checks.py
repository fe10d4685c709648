"""Input checks shared by every module: clear errors that name the parameter."""
from __future__ import annotations

import math
import numbers

import numpy as np

__all__ = ["check_positive", "finite_array", "check_dim", "check_skin", "resolve_dim", "DIM_RULE", "SphrelaxWarning", "SPHScaleWarning",
           "NotConvergedWarning", "SpacingWarning", "PluginWarning", "spacing_mismatch", "ASE_DEFAULT_FMAX"]

#: ``Optimizer.run(fmax=0.05)``: ASE's default, in eV/Angstrom
ASE_DEFAULT_FMAX = 0.05


class SphrelaxWarning(UserWarning):
    """Every warning of ase_sphrelax (and lammps_io) is of this class or a subclass of it.

    Filter them all with ``warnings.simplefilter("ignore", ase_sphrelax.SphrelaxWarning)``; the
    ``sphrelax`` command prints each one as one line, ``sphrelax COMMAND: warning: MESSAGE``.
    """


class PluginWarning(SphrelaxWarning, RuntimeWarning):
    """A ``sphrelax`` plug-in (entry point) was skipped or shadowed."""


class SPHScaleWarning(SphrelaxWarning):
    """Forces below ASE's default ``fmax``: an ASE optimiser run with its defaults stops at step 0."""


class NotConvergedWarning(SphrelaxWarning):
    """A run ended without reaching its own convergence criterion; the message names the criterion
    that failed (the result's ``info["converged"]`` is False and ``info["convergence_reason"]`` says why)."""


class SpacingWarning(SphrelaxWarning):
    """The particles are not at the spacing ``dx`` the model assumes (``N dx^d`` is not the region's measure)."""


def spacing_mismatch(n, dx, dim, measure, surface, name="dx"):
    """A one-line message when ``n`` particles of spacing ``dx`` cannot fill a region of ``measure``, else None.

    One particle per cell centre inside a region (:func:`ase_sphrelax.build.fill`) gives ``N dx^d`` that
    differs from the measure ``V`` only by the cells the boundary cuts: those with centres within
    ``sqrt(d) dx / 2`` of it, a band of measure at most ``surface sqrt(d) dx``. Beyond that bound the
    particles were placed at another spacing (or the region is another one).

    Parameters
    ----------
    n : int
    dx : float
    dim : int
    measure : float
        Area (2D), volume (3D) or length (1D) of the region.
    surface : float
        Its boundary's measure (perimeter, area; 2 in 1D).
    """
    if not (np.isfinite(measure) and measure > 0 and np.isfinite(surface)) or n == 0:
        return None
    filled = n * dx**dim
    band = surface * math.sqrt(dim) * dx
    if abs(filled - measure) <= band:
        return None
    implied = (measure / n) ** (1.0 / dim)
    return (f"{n} particles of {name}={dx:.6g} fill N {name}^{dim} = {filled:.6g}, but the region's measure is "
            f"{measure:.6g} (cell-centre fills differ by at most {band:.3g}): the particles are spaced about "
            f"{implied:.6g}; pass {name}={implied:.3g} or fill at {name}={dx:.6g}")


def check_positive(name, value, allow_none=False):
    """Return ``value`` as a finite float > 0.

    Raises TypeError naming ``name`` for a non-number (booleans included) and
    ValueError for NaN, infinity or a value <= 0. With ``allow_none``, None passes.
    """
    if value is None and allow_none:
        return None
    accepted = "a positive finite number" + (" or None" if allow_none else "")
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise TypeError(f"{name} must be {accepted}, got {value!r}")
    if not math.isfinite(value) or value <= 0:
        raise ValueError(f"{name} must be {accepted}, got {value!r}")
    return float(value)


def finite_array(name, value, n, shape=(), positive=False):
    """``value`` as a float array of shape ``(n, *shape)``, a scalar broadcast; one-line errors naming ``name``.

    Raises ValueError for a wrong shape, NaN or inf, or (``positive=True``) a value <= 0.
    """
    arr = np.asarray(value, dtype=float)
    if arr.ndim == 0:
        arr = np.full((n, *shape), float(arr))
    if arr.shape != (n, *shape):
        raise ValueError(f"{name} must have shape {(n, *shape)} (or be one number), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains NaN or inf: every value must be finite")
    if positive and np.any(arr <= 0):
        raise ValueError(f"{name} must be positive, got a minimum of {arr.min():.6g}")
    return arr


def check_dim(dim, allowed=(1, 2, 3)):
    """Return ``dim`` as an int in ``allowed`` (default {1, 2, 3}); ValueError naming ``dim`` otherwise.

    ``allowed=(2, 3)`` is the lattice theory's variant (no 1D lattices of patterns).
    """
    if isinstance(dim, (bool, np.bool_)) or not isinstance(dim, (int, np.integer)) or dim not in allowed:
        names = ", ".join(map(str, allowed[:-1])) + f" or {allowed[-1]}" if len(allowed) > 1 else str(allowed[0])
        raise ValueError(f"dim must be {names}, got {dim!r}")
    return int(dim)


def check_skin(skin, name="skin"):
    """Return a Verlet skin as a finite float >= 0."""
    if isinstance(skin, bool) or not isinstance(skin, numbers.Real) or not math.isfinite(skin) or skin < 0:
        raise ValueError(f"{name} must be a finite number >= 0, got {skin!r}")
    return float(skin)


# -- the one dimension rule ------------------------------------------------------------------
DIM_RULE = ("2D particles live at z = 0 with pbc (True, True, False) (1D: on the x axis); a cell periodic in z, "
            "or z that varies, is 3D")


def _flat(values, r_pc):
    """True when every value is 0, to round-off of the size of the coordinates ``r_pc``.

    The common case (exact zeros) costs one pass over ``values`` and allocates nothing large.
    """
    if not len(values) or not np.count_nonzero(values):  # the fastest pass over a strided column
        return True
    largest = max(float(values.max()), -float(values.min()))  # no temporaries of the size of the arrays
    return largest <= 1e-12 * max(1.0, float(r_pc.max()), -float(r_pc.min()))


def resolve_dim(atoms, dim=None, domain=None, name="dim", zero_axes=None):
    """The dimension of ``atoms``: one rule for calculators, analysis, build and ``lammps_io``.

    Parameters
    ----------
    atoms : ase.Atoms
    dim : {1, 2, 3} or None
        The dimension asked for; None infers it (from ``domain``, then ``atoms.info["dim"]``
        as :func:`ase_sphrelax.build.fill` and ``periodic_box`` set it, then the geometry).
    domain : Domain or None
        Its ``dim`` must agree with ``dim``; with ``dim`` None it decides.
    name : str
        How the caller calls the parameter, for the messages (e.g. ``"FanCalculator(dim=...)"``).
    zero_axes : (bool, bool), optional
        What the caller already knows of ``atoms.positions``: whether every y, every z is exactly 0
        (a calculator's one pass over them); None: looked at here.

    Returns
    -------
    int
        1, 2 or 3.

    Raises
    ------
    ValueError
        One line naming the mismatch and the remedy, never a silent projection:

        * inference: a cell periodic in z, or z that varies, is 3D; every z equal and not
          periodic in z is 2D, but only at z = 0 (every z at another value is ambiguous: an error
          naming both remedies); 2D with every y = 0 and not periodic in y is 1D;
        * 2D (1D) asked for or inferred: every z (y and z) must be 0 and the cell not periodic
          along the unused axes;
        * 3D asked for with at least two particles that all lie at z = 0 in a cell not periodic
          in z (2D particles) is an error unless ``atoms.info["dim"] == 3`` or a 3D ``domain``
          says so;
        * ``atoms.info["dim"]`` or ``domain.dim`` that disagrees with ``dim``.
    """
    if dim is not None:
        dim = check_dim(dim)
    domain_dim = getattr(domain, "dim", None) if domain is not None else None
    if domain_dim is not None and dim is not None and domain_dim != dim:
        raise ValueError(f"domain is {domain_dim}D but {name}={dim}: pass {name}={domain_dim} or {name}=None")
    declared = atoms.info.get("dim") if hasattr(atoms, "info") else None
    if declared is not None:
        try:
            declared = check_dim(declared)
        except ValueError:
            raise ValueError(f"atoms.info['dim'] must be 1, 2 or 3, got {declared!r}") from None
        asked = dim if dim is not None else domain_dim
        if asked is not None and asked != declared:
            who = f"{name}={asked}" if dim is not None else f"the {asked}D domain"
            raise ValueError(f"atoms.info['dim'] = {declared} (set when the atoms were built) but {who}: "
                             f"pass {name}={declared}, or set atoms.info['dim'] = {asked} if the atoms are {asked}D")
    r_pc = np.asarray(atoms.positions, dtype=float)
    pbc = np.asarray(atoms.pbc, dtype=bool)
    n = len(r_pc)
    target = dim if dim is not None else domain_dim if domain_dim is not None else declared
    # 3D: whether every z is 0 matters only when nothing declared the atoms 3D (the last check below)
    y_zero, z_zero = zero_axes if zero_axes is not None else (None, None)
    needed = target != 3 or (n >= 2 and not pbc[2] and 3 not in (declared, domain_dim))
    z_flat = bool(z_zero or _flat(r_pc[:, 2], r_pc)) if needed else False
    if target is None:  # infer from the geometry
        z_equal = z_flat or float(np.ptp(r_pc[:, 2])) <= 1e-12 * max(1.0, float(np.abs(r_pc).max()))
        if pbc[2] or not z_equal:
            return 3
        if not z_flat:
            raise ValueError(f"atoms: every particle has z = {r_pc[0, 2]:.6g} and the cell is not periodic in z, "
                             f"so the dimension is ambiguous: 2D particles must lie at z = 0 (shift them: "
                             f"atoms.positions[:, 2] = 0), a flat 3D set needs {name}=3")
        if pbc[1] or not (y_zero or _flat(r_pc[:, 1], r_pc)):
            return 2
        return 1
    if target < 3:
        unused = "z" if target == 2 else "y and z"
        if np.any(pbc[target:]):
            raise ValueError(f"a {target}D system cannot be periodic along {unused} (atoms.pbc = {pbc.tolist()}): "
                             f"set atoms.pbc[{target}:] = False, or pass {name}=3 for 3D atoms ({DIM_RULE})")
        for k in range(target, 3):
            if not (z_flat if k == 2 else y_zero or _flat(r_pc[:, k], r_pc)):
                bad = np.nonzero(np.abs(r_pc[:, k]) > 1e-12 * max(1.0, float(np.abs(r_pc).max())))[0]
                raise ValueError(f"a {target}D system needs every particle at {'xyz'[k]} = 0, but {len(bad)} have "
                                 f"{'xyz'[k]} != 0 (non-zero coordinates beyond axis {target - 1}; e.g. particle "
                                 f"{int(bad[0])} at {'xyz'[k]} = "
                                 f"{r_pc[bad[0], k]:.6g}): pass {name}=3 for 3D atoms, or put 2D particles at "
                                 f"z = 0; they are never flattened silently")
        return target
    if n >= 2 and not pbc[2] and z_flat and declared != 3 and domain_dim != 3:
        raise ValueError(f"{name}=3 but every particle lies at z = 0 and the cell is not periodic in z (2D atoms): "
                         f"pass {name}=2 or {name}=None; for a flat layer of a 3D set give a 3D domain or set "
                         f"atoms.info['dim'] = 3")
    return target
