"""The step scale shared by Fan's Eq. 2.4 driver and the scaled ASE optimisers.

Both move the fastest particle by ``c h`` (Eq. 2.4/2.5): :func:`check_c` validates ``c``,
:func:`calculator_h` finds ``h`` on the calculator, :func:`mark_scaled` silences the
ASE-defaults hint of a calculator run by a scaled driver, and :func:`warn_if_nothing_relaxed`
warns when a run with ``fmax > 0`` stopped at step 0. Light: imports no ASE optimiser and no numba.
"""
from __future__ import annotations

import math
import numbers
import warnings

from ..checks import SphrelaxWarning, check_positive

__all__ = ["NothingRelaxedWarning", "check_c", "calculator_h", "mark_scaled", "warn_if_nothing_relaxed"]


class NothingRelaxedWarning(SphrelaxWarning):
    """An optimiser run stopped at step 0 because ``fmax`` exceeded every force: nothing was relaxed."""


def check_c(c, name="c"):
    """The step scale ``c`` of Eq. 2.4 (step ``c h``) as a float in (0, 1).

    ``c >= 1`` moves a particle by more than the kernel support per step: it jumps over its
    neighbours and out of the domain (``--c 5`` left 298 particles outside), so it is refused.
    """
    c = check_positive(name, c)
    if c >= 1.0:
        raise ValueError(f"{name} must be < 1 (a step of c h >= h jumps over the kernel support; Fan uses 0.01), "
                         f"got {c!r}")
    return c


def _calculator_of(atoms):
    """The calculator of ``atoms`` or of the Atoms inside a Filter, or None."""
    calc = getattr(atoms, "calc", None)
    if calc is None and hasattr(atoms, "atoms"):  # a Filter
        calc = getattr(atoms.atoms, "calc", None)
    return calc


def calculator_h(atoms):
    """The kernel support ``h`` of the calculator of ``atoms`` (or of a Filter's Atoms), or None."""
    params = getattr(_calculator_of(atoms), "parameters", {}) or {}
    return params.get("h")


def mark_scaled(atoms):
    """Tell the calculator of ``atoms`` that a scaled driver runs it: no :class:`SPHScaleWarning` hint."""
    calc = _calculator_of(atoms)
    if calc is not None:
        getattr(calc, "silence_scale_hint", lambda: None)()  # an SPHCalculator; other calculators never hint


def warn_if_nothing_relaxed(optimizer, fmax, converged):
    """Warn (:class:`NothingRelaxedWarning`) when a run with ``fmax > 0`` converged at step 0."""
    if converged and optimizer.nsteps == 0 and isinstance(fmax, numbers.Real) and fmax > 0 and math.isfinite(fmax):
        warnings.warn(f"{type(optimizer).__name__}.run(fmax={fmax:g}) stopped at step 0: every force is below fmax, "
                      "so nothing was relaxed. SPH forces are small (Fan's are about 4e-3 on the default circle, "
                      "while ASE's default fmax = 0.05 is for eV/Angstrom): give fmax relative to the forces, e.g. "
                      "1e-3 * max |F|, or fmax=0 to run all steps", NothingRelaxedWarning, stacklevel=3)
