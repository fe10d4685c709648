"""Input checks shared by every module: clear errors that name the parameter."""
from __future__ import annotations

import math
import numbers

import numpy as np

__all__ = ["check_positive", "check_dim", "check_skin"]


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
