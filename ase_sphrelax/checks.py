"""Input checks shared by every module: clear errors that name the parameter."""
from __future__ import annotations

import math
import numbers

__all__ = ["check_positive"]


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
