"""Shared plumbing for the SPH relaxation calculators.

:class:`SPHCalculator` validates parameters (ASE's ``Calculator.set`` would
store unknown keywords silently), validates Atoms before any work, resolves
their dimension by the package's one rule (:func:`ase_sphrelax.checks.resolve_dim`: a
mismatch is an error, never a silent projection) and keeps one Verlet neighbour list per
calculator. Method calculators (Fan, BIPI, ALARIC, SPH-ParVI) subclass it.
"""
from __future__ import annotations

import numba
import numpy as np
from ase.calculators.calculator import Calculator, Parameters, all_changes

from ..checks import ASE_DEFAULT_FMAX, SPHScaleWarning, check_dim, resolve_dim
from ..kernels import KERNEL_NAMES
from ..neighbors import NeighborList

__all__ = ["SPHCalculator", "periodic_measure", "SPHScaleWarning", "ASE_DEFAULT_FMAX"]


def periodic_measure(cell, pbc, dim):
    """Length (1D), area (2D) or volume (3D) of the cell if periodic along all ``dim`` axes, else None."""
    pbc = np.asarray(pbc, dtype=bool)
    if not np.all(pbc[:dim]):
        return None
    vectors = np.asarray(cell, dtype=float)[:dim, :]
    return float(np.sqrt(abs(np.linalg.det(vectors @ vectors.T))))


@numba.njit(cache=True)
def _same_values(a, b):
    """Exact equality of two arrays of one shape, without the temporary of ``a == b``."""
    a = a.ravel()
    b = b.ravel()
    for i in range(a.shape[0]):
        if a[i] != b[i]:
            return False
    return True


@numba.njit(cache=True)
def _all_finite(r_pc):
    """``np.isfinite(r_pc).all()`` without the boolean temporary: an and-reduction without an
    early exit, which the compiler vectorises (1e5 x 3: 0.03 ms; numpy 0.05 ms, a loop that
    returns at the first non-finite value 0.2 ms)."""
    r = r_pc.ravel()
    ok = True
    for i in range(r.shape[0]):
        ok &= np.isfinite(r[i])
    return ok


def _equal(a, b):
    """``np.array_equal`` for the per-particle arrays of check_state: several calls per
    optimiser step, where numpy's allocation and dispatch cost more than the compare."""
    if a.shape != b.shape or a.dtype != b.dtype or not (a.flags.c_contiguous and b.flags.c_contiguous):
        return np.array_equal(a, b)
    return _same_values(a, b)


class SPHCalculator(Calculator):
    """Base class: parameter checking, Atoms checking and the neighbour list.

    Subclasses define ``default_parameters``, ``_validate_parameters()`` and
    ``calculate()``, and call :meth:`prepare` at the start of ``calculate``; the
    pair sums (:mod:`ase_sphrelax.pairs`) then run over ``self.nlist``, whatever its state.

    Class attributes
    ----------------
    velocity_dependent : bool
        True for forces that depend on the momenta (viscosity, friction): then
        :meth:`check_state` compares momenta too, so that a velocity change is never
        served from the cache.
    """

    nolabel = True
    default_parameters: dict = {}
    velocity_dependent = False

    def __init__(self, **kwargs):
        self._check_keys(kwargs)
        self.nlist = None
        self._evaluations = 0
        self._valid = False
        Calculator.__init__(self, **kwargs)
        self._validate_parameters()
        self._valid = True

    @property
    def pairs(self):
        """The neighbour list of the last :meth:`prepare` (an alias of ``nlist``)."""
        return self.nlist

    def todict(self, skip_default=True):
        """Parameters for ASE's trajectory and JSON writers.

        Values that are not plain data (a domain, a target density as a Python callable) are
        written as their ``repr``: writing a ``.traj`` must not fail because of them.
        """
        import json

        from ase.io.jsonio import MyEncoder

        out = {}
        for key, value in Calculator.todict(self, skip_default=skip_default).items():
            try:
                json.dumps(value, cls=MyEncoder)
            except TypeError:
                value = repr(value)
            out[key] = value
        return out

    def _check_keys(self, kwargs):
        unknown = set(kwargs) - set(self.default_parameters)
        if unknown:
            raise TypeError(f"{type(self).__name__} got unknown parameter(s) {sorted(unknown)}; "
                            f"accepted: {sorted(self.default_parameters)}")

    def set(self, **kwargs):
        """Change parameters; any change discards the results and the neighbour list.

        Invalid values raise before anything changes: the calculator keeps its old parameters.
        """
        self._check_keys(kwargs)
        before = Parameters(self.parameters)
        changed = Calculator.set(self, **kwargs)
        if changed:
            try:
                self._validate_parameters()
            except Exception:
                self.parameters = before
                if self._valid:  # derived state (models, kernels) back to the old parameters
                    self._validate_parameters()
                raise
            self.reset()  # ASE keeps results on set() unless told otherwise
            self.nlist = None
            self._evaluations = 0
        return changed

    def _validate_parameters(self):
        p = self.parameters
        p.dim = None if p.get("dim") is None else check_dim(p.dim)
        if "kernel" in p and p.kernel not in KERNEL_NAMES:
            raise ValueError(f"kernel must be one of {KERNEL_NAMES}, got {p.kernel!r}")

    # -- per-call preparation ---------------------------------------------------
    def resolve_dim(self, atoms):
        """The dimension of ``atoms`` for this calculator: ``parameters.dim`` (None: inferred) checked
        against the atoms and ``parameters.domain`` by :func:`ase_sphrelax.checks.resolve_dim`.

        Every calculator calls it (directly or through :meth:`prepare`) before any work: 3D atoms
        with ``dim=2``, 2D atoms with ``dim=3`` and 2D atoms off z = 0 are one-line errors.
        """
        if atoms is None or len(atoms) == 0:
            raise ValueError("atoms: need at least one particle, got an empty Atoms")
        if not _all_finite(atoms.positions):
            bad = np.where(~np.all(np.isfinite(atoms.positions), axis=1))[0]
            raise ValueError(f"atoms.positions must be finite; particles {bad[:10].tolist()} are NaN or inf")
        p = self.parameters
        return resolve_dim(atoms, p.get("dim"), p.get("domain"))

    def prepare(self, atoms, cutoff, skin, dim=None):
        """Validate ``atoms`` and update ``self.nlist``; return in-plane positions r_pc and the effective pbc.

        ``cutoff`` (a number or one per particle) is taken on every call. The first
        evaluation leaves the list in its one-shot state (pair sums fused into the bin
        scan); the Verlet list is built from the second evaluation on, when it can be
        reused. ``dim`` is the result of :meth:`resolve_dim` (None: resolved here); the
        coordinates beyond it are zero and not periodic, or :meth:`resolve_dim` raised.

        ``r_pc`` is ``atoms.positions`` itself when no coordinate needs zeroing (2D atoms at
        z = 0, 3D): do not modify it in place.
        """
        dim = self.resolve_dim(atoms) if dim is None else dim  # also: not empty, finite
        r_pc = atoms.positions
        if r_pc.dtype != np.float64 or (dim < 3 and r_pc[:, dim:].any()):
            r_pc = np.array(r_pc, dtype=float)  # a copy: the caller's positions stay as they are
            r_pc[:, dim:] = 0.0  # round-off only: resolve_dim refused anything else
        pbc = np.array(atoms.pbc, dtype=bool)
        pbc[dim:] = False
        if self.nlist is None or self.nlist.skin != skin:
            self.nlist = NeighborList(cutoff, skin=skin)
        self.nlist.update(r_pc, atoms.cell.array, pbc, cutoff=cutoff, store=self._evaluations > 0)
        self._evaluations += 1
        return r_pc, pbc

    def hint_force_scale(self, f_pc):
        """Warn once per calculator (:class:`SPHScaleWarning`) when 0 < max |F| < ASE's default fmax.

        A user who follows ASE's habits (``FIRE(atoms).run(fmax=0.05)``) would otherwise get an
        unrelaxed result without a word (issue 10 item 8). The message is constant, so Python
        shows it once per place; silence it with ``warnings.simplefilter("ignore", SPHScaleWarning)``.
        """
        if getattr(self, "_scale_hinted", False):
            return
        self._scale_hinted = True
        f_max = float(np.sqrt((np.asarray(f_pc) ** 2).sum(axis=1)).max()) if len(f_pc) else 0.0
        if 0.0 < f_max < ASE_DEFAULT_FMAX:
            import warnings

            warnings.warn(f"{type(self).__name__}: every force is below 0.05, ASE's default fmax (eV/Angstrom): "
                          "an ASE optimiser run with its defaults, e.g. FIRE(atoms).run(fmax=0.05), stops at "
                          "step 0 and relaxes nothing. Use ase_sphrelax.drivers.make_optimizer(name, atoms) and "
                          "run(fmax=...) with fmax relative to the forces (README: 'ASE optimisers at SPH "
                          "scales')", SPHScaleWarning, stacklevel=4)

    def check_state(self, atoms, tol=1e-15):
        """Which of positions, numbers, cell, pbc (and momenta, for velocity-dependent
        forces) changed, by exact comparison.

        ASE's generic ``compare_atoms`` runs ``np.isclose`` over every array on every
        property request, which costs more than a relaxation step of a small system.
        """
        if self.atoms is None or len(atoms) != len(self.atoms):
            return list(all_changes) + (["momenta"] if self.velocity_dependent else [])
        changes = []
        if not _equal(atoms.positions, self.atoms.positions):
            changes.append("positions")
        if not _equal(atoms.numbers, self.atoms.numbers):
            changes.append("numbers")
        if not np.array_equal(atoms.cell.array, self.atoms.cell.array):
            changes.append("cell")
        if not np.array_equal(atoms.pbc, self.atoms.pbc):
            changes.append("pbc")
        if self.velocity_dependent and not _equal(atoms.get_momenta(), self.atoms.get_momenta()):
            changes.append("momenta")
        return changes

    def calculate(self, atoms=None, properties=("energy",), system_changes=all_changes):
        Calculator.calculate(self, atoms, properties, system_changes)
