"""The one calculator contract of the package (ARCHITECTURE.md, "Adding a method").

:meth:`SPHCalculator.calculate` does the shared steps for every method, in one place:
parameter checks (ASE's ``Calculator.set`` would store unknown keywords silently), Atoms
checks, the dimension by the package's one rule (:func:`ase_sphrelax.checks.resolve_dim`:
``dim=None`` infers it, a mismatch is an error, never a silent projection), the neighbour
list (:meth:`SPHCalculator.prepare`), the refusal of an energy for non-conservative forces,
``free_energy = energy``, the force-scale hint and storing the results. A method supplies its
model's evaluation, :meth:`SPHCalculator.evaluate` (an :class:`EvaluationState` in, the
requested properties out), and a few small hooks. Method calculators (Fan, BIPI, ALARIC,
SPH-ParVI, Fan in LAMMPS) subclass it.
"""
from __future__ import annotations

import copy
import sys
import weakref
from dataclasses import dataclass

import numba
import numpy as np
from ase import Atoms
from ase.calculators.calculator import Calculator, Parameters, PropertyNotImplementedError, all_changes

from ..checks import ASE_DEFAULT_FMAX, SPHScaleWarning, check_dim, resolve_dim
from ..kernels import KERNEL_NAMES
from ..neighbors import NeighborList
from ..parallel import copy_rows, reduce_chunks

__all__ = ["SPHCalculator", "EvaluationState", "periodic_measure", "SPHScaleWarning", "ASE_DEFAULT_FMAX",
           "ENERGY_PROPERTIES"]

#: what a non-conservative calculator refuses: its forces are not minus the gradient of any energy
ENERGY_PROPERTIES = ("energy", "free_energy", "energies", "stress")


def periodic_measure(cell, pbc, dim):
    """Length (1D), area (2D) or volume (3D) of the cell if periodic along all ``dim`` axes, else None."""
    pbc = np.asarray(pbc, dtype=bool)
    if not np.all(pbc[:dim]):
        return None
    vectors = np.asarray(cell, dtype=float)[:dim, :]
    return float(np.sqrt(abs(np.linalg.det(vectors @ vectors.T))))


@numba.njit(cache=True, nogil=True)
def _same_values_chunk(a, b, out, first, last):
    """out[0] = 0 when ``a[first:last]`` and ``b[first:last]`` (flat) differ somewhere (a chunk of :func:`_equal`)."""
    for i in range(first, last):
        if a[i] != b[i]:
            out[0] = 0.0
            return


@numba.njit(cache=True, nogil=True)
def _scan_positions_chunk(r_pc, copy_pc, copy, out, first, last):
    finite = True
    y_zero = True
    z_zero = True
    for p in range(first, last):
        x, y, z = r_pc[p, 0], r_pc[p, 1], r_pc[p, 2]
        if copy:
            copy_pc[p, 0] = x
            copy_pc[p, 1] = y
            copy_pc[p, 2] = z
        finite &= np.isfinite(x) & np.isfinite(y) & np.isfinite(z)
        y_zero &= y == 0.0
        z_zero &= z == 0.0
    out[0] = min(out[0], 1.0 if finite else 0.0)
    out[1] = min(out[1], 1.0 if y_zero else 0.0)
    out[2] = min(out[2], 1.0 if z_zero else 0.0)


def _scan_positions(r_pc, copy_pc=None):
    """One pass over positions (P, 3): ``(every coordinate finite, every y exactly 0, every z exactly 0)``
    (three numpy passes cost 3x as much at 1e6 particles: 2.5 ms each), in :func:`thread_count` chunks. An
    and-reduction without an early exit, which the compiler vectorises. ``copy_pc`` (P, 3) float64: the positions
    are copied into it in the same pass (the calculator's snapshot)."""
    copy = copy_pc is not None
    outs = reduce_chunks(_scan_positions_chunk, r_pc.shape[0], (r_pc, copy_pc if copy else r_pc, copy), 3, fill=1.0)
    return tuple(all(out[k] == 1.0 for out in outs) for k in range(3))


def check_store_list(store_list):
    """The ``store_list`` parameter of ALARIC's and BIPI's calculators: True, False or None; one line otherwise."""
    if store_list is not None and not isinstance(store_list, (bool, np.bool_)):
        raise ValueError(f"store_list must be True, False or None (a stored list in 1D and 2D, none in 3D), "
                         f"got {store_list!r}")
    return store_list


def resolve_store_list(store_list, dim):
    """Whether evaluations after the first keep a Verlet list: ``store_list`` as given, or for None (the default)
    a list in 1D and 2D and one-shot bins in 3D, where the list alone holds 440 (ALARIC, mirror ghosts) to 630
    (BIPI, ``h = 4 dx``) bytes per particle at 1e5 particles, and a step without it costs about 1.2x the CPU time
    (``reproductions/speed-scale-memory-alaric``; issue 33's goal: at most 900 B per particle in 3D)."""
    return dim < 3 if store_list is None else bool(store_list)


def _equal(a, b):
    """``np.array_equal`` for the per-particle arrays of check_state: several calls per
    optimiser step, where numpy's allocation and dispatch cost more than the compare."""
    if a.shape != b.shape or a.dtype != b.dtype or not (a.flags.c_contiguous and b.flags.c_contiguous):
        return np.array_equal(a, b)
    a, b = a.reshape(-1), b.reshape(-1)  # views (contiguous)
    return all(out[0] == 1.0 for out in reduce_chunks(_same_values_chunk, a.shape[0], (a, b), 1, fill=1.0))


@dataclass
class EvaluationState:
    """What :meth:`SPHCalculator.evaluate` receives: the checked Atoms, in the resolved dimension.

    Attributes
    ----------
    atoms : ase.Atoms
        The calculator's copy of the Atoms (read only).
    dim : int
        1, 2 or 3, by :func:`ase_sphrelax.checks.resolve_dim`.
    r_pc : ndarray (N, 3)
        Positions, zero beyond ``dim`` (may be ``atoms.positions`` itself: do not modify).
    pbc : ndarray (3,) of bool
        Periodicity, False beyond ``dim``.
    cell : ndarray (3, 3)
    nlist : NeighborList or None
        ``self.nlist`` updated for :meth:`SPHCalculator.cutoff`; None when the method keeps its own.
    v_pc : ndarray (N, 3) or None
        Velocities, for ``velocity_dependent`` calculators with momenta set; else None.
    first : bool
        The first evaluation since construction or :meth:`~SPHCalculator.set` (one-shot list).
    """

    atoms: object
    dim: int
    r_pc: np.ndarray
    pbc: np.ndarray
    cell: np.ndarray
    nlist: object
    v_pc: np.ndarray
    first: bool


class SPHCalculator(Calculator):
    """Base class: the shared steps of every method's ``calculate``.

    A method supplies (ARCHITECTURE.md, "Adding a method"):

    * ``default_parameters`` with ``dim=None`` (inferred from the Atoms) and
      ``implemented_properties``;
    * ``_validate_parameters()``: reject bad input at construction and ``set()`` (call super);
    * ``configure(dim)`` (optional): build what depends on the dimension (a model, a kernel),
      called when the resolved dimension is first known or changes;
    * ``check_atoms(atoms, dim, properties)`` (optional): the method's own rules (open space,
      particle count, stress needs a periodic cell), after the shared ones (not empty, finite,
      :meth:`resolve_dim`);
    * ``cutoff(atoms, dim)``: ``(cutoff, skin)`` of the neighbour list (a number or one per
      particle), or None when the model keeps its own list;
    * ``evaluate(state, properties)``: the model's evaluation (:class:`EvaluationState` in,
      a dict of results out, holding at least the requested properties);
    * ``conservative`` (a class attribute or a property) and ``velocity_dependent``.

    Non-conservative forms (``conservative`` False) compute forces only: asking for
    ``energy``, ``free_energy``, ``energies`` or ``stress`` raises ASE's
    :class:`~ase.calculators.calculator.PropertyNotImplementedError`, and a method's monitor
    quantity, if any, is the separate result ``"monitor"`` (:meth:`monitor`).

    Class attributes
    ----------------
    conservative : bool
        True when the forces (and stress) are exact derivatives of the reported energy.
    velocity_dependent : bool
        True for forces that depend on the momenta (viscosity, friction): then
        :meth:`check_state` compares momenta too, so that a velocity change is never
        served from the cache, and :class:`EvaluationState` carries the velocities.
    """

    nolabel = True
    default_parameters: dict = {}
    velocity_dependent = False
    conservative = True

    def __init__(self, **kwargs):
        self._check_keys(kwargs)
        self.nlist = None
        self._evaluations = 0
        self._valid = False
        self._scale_hinted = False
        self.dim = None
        Calculator.__init__(self, **kwargs)
        self._validate_parameters()
        self._valid = True

    @property
    def pairs(self):
        """The neighbour list of the last :meth:`prepare` (an alias of ``nlist``)."""
        return self.nlist

    @property
    def evaluations(self):
        """Evaluations since construction, :meth:`set` or :meth:`forget_neighbours` (the first is one-shot)."""
        return self._evaluations

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
            self.dim = None  # configure() again at the next evaluation
            try:
                self._validate_parameters()
            except Exception:
                self.parameters = before
                if self._valid:  # derived state (models, kernels) back to the old parameters
                    self._validate_parameters()
                raise
            self.forget_neighbours()  # and the results: ASE keeps them on set() unless told otherwise
        return changed

    def _validate_parameters(self):
        p = self.parameters
        p.dim = None if p.get("dim") is None else check_dim(p.dim)
        if "kernel" in p and p.kernel not in KERNEL_NAMES:
            raise ValueError(f"kernel must be one of {KERNEL_NAMES}, got {p.kernel!r}")

    # -- public controls for drivers ----------------------------------------------------------
    def forget_neighbours(self):
        """Discard the neighbour list and the results: the next evaluation starts one-shot (e.g.
        after the particles were split or replaced)."""
        self.nlist = None
        self._evaluations = 0
        self.reset()

    def clone(self):
        """A fresh calculator of the same class and parameters (no results, no neighbour list)."""
        return type(self)(**self.parameters)

    def validate_atoms(self, atoms):
        """Every check of an evaluation on ``atoms`` (shared and the method's), without evaluating; returns dim."""
        dim = self.use_dim(atoms)
        self.check_atoms(atoms, dim, ())
        return dim

    def silence_scale_hint(self):
        """No :class:`SPHScaleWarning` from this calculator: a driver that scales its steps runs it."""
        self._scale_hinted = True

    def monitor(self, atoms=None):
        """The method's monitor quantity (result ``"monitor"``; e.g. ALARIC's log potential in the
        paper's non-conservative form), computed with the forces; None when the method has none."""
        if atoms is not None or "monitor" not in self.results:
            self.get_forces(atoms)
        return self.results.get("monitor")

    # -- the hooks of a method ------------------------------------------------------------------
    def configure(self, dim):
        """Build what depends on the dimension (models, kernels); called when ``dim`` is first
        resolved or changes. Default: nothing."""

    def check_atoms(self, atoms, dim, properties):
        """The method's own rules on ``atoms`` and the requested ``properties`` (e.g. stress needs a
        periodic cell), after the shared ones; raise a one-line error before any work. Default: none."""

    def cutoff(self, atoms, dim):
        """``(cutoff, skin)`` of ``self.nlist`` for this evaluation, or None (the model keeps its own list)."""
        raise NotImplementedError(f"{type(self).__name__} must define cutoff(atoms, dim)")

    def evaluate(self, state, properties):
        """The model's evaluation: a dict with (at least) the requested ``properties``."""
        raise NotImplementedError(f"{type(self).__name__} must define evaluate(state, properties)")

    def non_conservative_reason(self):
        """Why the forces are not a gradient (for the PropertyNotImplementedError of the energy)."""
        return f"{type(self).__name__} with these parameters"

    # -- per-call preparation ---------------------------------------------------
    def resolve_dim(self, atoms):
        """The dimension of ``atoms`` for this calculator: ``parameters.dim`` (None: inferred) checked
        against the atoms and ``parameters.domain`` by :func:`ase_sphrelax.checks.resolve_dim`.

        :meth:`calculate` calls it before any work: 3D atoms with ``dim=2``, 2D atoms with
        ``dim=3`` and 2D atoms off z = 0 are one-line errors.
        """
        if atoms is None or len(atoms) == 0:
            raise ValueError("atoms: need at least one particle, got an empty Atoms")
        r_pc = np.asarray(atoms.positions, dtype=float)
        scanned = self.__dict__.pop("_scanned_positions", None)  # the snapshot's copy scanned them (_take_snapshot)
        finite, y_zero, z_zero = scanned[1] if scanned is not None and scanned[0] is r_pc else _scan_positions(r_pc)
        if not finite:
            bad = np.where(~np.all(np.isfinite(r_pc), axis=1))[0]
            raise ValueError(f"atoms.positions must be finite; particles {bad[:10].tolist()} are NaN or inf")
        self._zero_axes = (False, y_zero, z_zero)  # for prepare, in the same evaluation
        p = self.parameters
        return resolve_dim(atoms, p.get("dim"), p.get("domain"), zero_axes=(y_zero, z_zero))

    def use_dim(self, atoms):
        """Resolve the dimension of ``atoms`` and :meth:`configure` the method for it; returns it."""
        dim = self.resolve_dim(atoms)
        if dim != self.dim:
            self.configure(dim)
            self.dim = dim
        return dim

    def stores_list(self):
        """Whether evaluations after the first keep a Verlet list (True here; a method may choose one-shot bins
        at every evaluation, trading a bin scan per evaluation for the list's memory)."""
        return True

    def max_skin(self, skin, dim):
        """The largest skin of an adaptive list (``NeighborList``'s ``max_skin``), or None: a fixed ``skin``."""
        return None

    def prepare(self, atoms, cutoff, skin, dim=None):
        """Validate ``atoms`` and update ``self.nlist``; return in-plane positions r_pc and the effective pbc.

        ``cutoff`` (a number or one per particle) is taken on every call. The first
        evaluation leaves the list in its one-shot state (pair sums fused into the bin
        scan); the Verlet list is built from the second evaluation on, when it can be
        reused. ``dim`` is the result of :meth:`resolve_dim` (None: resolved here); the
        coordinates beyond it are zero and not periodic, or :meth:`resolve_dim` raised.
        ``cutoff`` None: no list (the model keeps its own).

        ``r_pc`` is ``atoms.positions`` itself when no coordinate needs zeroing (2D atoms at
        z = 0, 3D): do not modify it in place.
        """
        dim = self.resolve_dim(atoms) if dim is None else dim  # also: not empty, finite
        r_pc = atoms.positions
        zero = self.__dict__.pop("_zero_axes", None)  # resolve_dim's pass over these positions, if it made one
        exact = all(zero[dim:]) if zero is not None else not r_pc[:, dim:].any()
        if r_pc.dtype != np.float64 or (dim < 3 and not exact):
            r_pc = np.array(r_pc, dtype=float)  # a copy: the caller's positions stay as they are
            r_pc[:, dim:] = 0.0  # round-off only: resolve_dim refused anything else
        pbc = np.array(atoms.pbc, dtype=bool)
        pbc[dim:] = False
        if cutoff is not None:
            max_skin = self.max_skin(skin, dim)
            if self.nlist is None or (self.nlist.min_skin, self.nlist.max_skin) != (skin, max_skin or skin):
                self.nlist = NeighborList(cutoff, skin=skin, max_skin=max_skin)
            self.nlist.update(r_pc, atoms.cell.array, pbc, cutoff=cutoff,
                              store=self._evaluations > 0 and self.stores_list(),
                              moved_at_most=self.__dict__.pop("_moved_at_most", None))
        self._evaluations += 1
        return r_pc, pbc

    def hint_force_scale(self, f_pc):
        """Warn once per calculator (:class:`SPHScaleWarning`) when ``0 < max |F|`` < ASE's default fmax.

        A user who follows ASE's habits (``FIRE(atoms).run(fmax=0.05)``) would otherwise get an
        unrelaxed result without a word (issue 10 item 8). The message is constant, so Python
        shows it once per place; silence it with ``warnings.simplefilter("ignore", SPHScaleWarning)``
        or, for one calculator, :meth:`silence_scale_hint`.
        """
        if self._scale_hinted:
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
        return self._changes(atoms)

    def _changes(self, atoms, moved=False, numbers_kept=False):
        """:meth:`check_state`'s list; ``moved``: "positions" without comparing them; ``numbers_kept``: the caller
        vouches that the numbers are those of the last evaluation (not compared)."""
        if self.atoms is None or len(atoms) != len(self.atoms):
            return list(all_changes) + (["momenta"] if self.velocity_dependent else [])
        changes = []
        if moved or not _equal(atoms.positions, self.atoms.positions):
            changes.append("positions")
        if not numbers_kept and not _equal(atoms.numbers, self.atoms.numbers):
            changes.append("numbers")
        if not np.array_equal(atoms.cell.array, self.atoms.cell.array):
            changes.append("cell")
        if not np.array_equal(atoms.pbc, self.atoms.pbc):
            changes.append("pbc")
        if self.velocity_dependent and not _equal(atoms.get_momenta(), self.atoms.get_momenta()):
            changes.append("momenta")
        return changes

    def _take_snapshot(self, atoms, skip=()):
        """``self.atoms = atoms.copy()`` (as ASE's ``Calculator.calculate``) without the arrays named in ``skip``,
        each array copied into the previous copy's array of that name where shape and type agree: no new pages
        for the positions at every evaluation (at 1e6 particles ASE's copy cost 5 ms, half of it page faults).

        Only while nothing but this calculator holds the previous copy and the array: a copy (or an array of it) that
        a caller kept stays as it was, and the new copy gets new arrays."""
        # the arrays of the previous copy (kept here: ASE's get_property drops self.atoms when the positions change)
        previous = self.__dict__.pop("_snapshot_arrays", {})
        if previous and not self._snapshot_unshared():
            previous = {}
        if type(atoms) is not Atoms:  # a subclass copies itself
            snapshot = atoms.copy()
            for name in skip:
                snapshot.arrays.pop(name, None)
            self.atoms = snapshot
            return
        # Atoms.copy, step by step
        snapshot = Atoms(cell=atoms.cell, pbc=atoms.pbc, info=atoms.info, celldisp=atoms.get_celldisp())
        snapshot.arrays = {}
        for name, values in atoms.arrays.items():
            if name in skip:
                continue
            kept = previous.get(name)
            # held by ``previous``, ``kept`` and getrefcount's argument only: no one else reads it
            if kept is not None and kept is not values and kept.shape == values.shape and kept.dtype == values.dtype \
                    and sys.getrefcount(kept) <= 3:
                if name == "positions" and kept.dtype == np.float64 and kept.shape[1:] == (3,) \
                        and kept.flags.c_contiguous and values.flags.c_contiguous:
                    # copied and scanned in one pass: resolve_dim, next in calculate, takes the scan
                    self._scanned_positions = (kept, _scan_positions(values, copy_pc=kept))
                elif kept.ndim <= 2:
                    copy_rows(kept, values)
                else:
                    np.copyto(kept, values)
                snapshot.arrays[name] = kept
            else:
                snapshot.arrays[name] = values.copy()
        snapshot.constraints = copy.deepcopy(atoms.constraints)
        self.atoms = snapshot
        self._snapshot_arrays = snapshot.arrays
        self._snapshot_ref = weakref.ref(snapshot)

    def _snapshot_unshared(self):
        """True when the previous copy of the atoms is gone or held by ``self.atoms`` alone."""
        ref = self.__dict__.get("_snapshot_ref")
        old = ref() if ref is not None else None
        if old is None:
            return True
        # ``old``, getrefcount's argument and, if it is still there, ``self.atoms``
        return sys.getrefcount(old) <= 2 + (self.__dict__.get("atoms") is old)

    def reset(self):
        """ASE's ``reset`` (drops the results and the copy of the atoms); the dropped results' forces array is kept
        aside for the next evaluation to write into (:meth:`spare_forces`)."""
        forces = self.__dict__.get("results", {}).get("forces")
        Calculator.reset(self)
        self._spare_forces = forces

    def spare_forces(self, n):
        """The forces array (n, 3) of the results :meth:`reset` dropped, for this evaluation to write its forces into,
        when nothing but this calculator holds it (no view of it either; ``get_forces`` hands out copies): its pages
        are in memory already, where a fresh array's cost more than the pass that fills them at 1e6 particles (the
        fold of Fan's pair sums: 9 against 3 ms). Else None. Taken once: a second call gives None."""
        forces = self.__dict__.pop("_spare_forces", None)
        if not isinstance(forces, np.ndarray) or forces.base is not None or forces.shape != (n, 3) \
                or forces.dtype != np.float64 or not forces.flags.c_contiguous or not forces.flags.writeable:
            return None
        # ``forces`` and getrefcount's argument only (a view of it, as forces_view's, holds it as its base)
        return forces if sys.getrefcount(forces) <= 2 else None

    def forces_view(self, atoms, moved=False, moved_at_most=None, only_positions=False):
        """The forces on ``atoms`` as ``get_forces`` (ASE's cache, an evaluation when needed), without the copy:
        a read-only view of this calculator's result, valid until its next evaluation.

        For drivers that read the forces once per step and keep nothing
        (:class:`~ase_sphrelax.drivers.sph_optimizers.SPHFIRE`): at 1e6 particles the copy cost 6 ms a step.
        Constraints are not applied (``Atoms.get_forces`` would): the driver decides whether that matters.
        ``moved``: the caller has just set the positions (a step): they count as changed without the comparison
        (a pass over 2 N positions); numbers, cell and pbc are compared as always. ``moved_at_most`` (with
        ``moved``): no particle moved further than this since this calculator's last evaluation (the step's longest
        move, constraints included), passed to the neighbour list (:meth:`~ase_sphrelax.neighbors.NeighborList.update`),
        which then need not measure the displacements while their bound stays under half its skin.
        ``only_positions`` (with ``moved``): nothing but the positions can have changed since this calculator's last
        evaluation of these atoms (an optimiser's ``run`` without observers: no other code ran between): the atoms'
        numbers are not compared either (cell and pbc are, they are small).
        """
        system_changes = self._changes(atoms, moved, only_positions and moved)
        if system_changes:
            self.reset()
        if "forces" not in self.results:
            self._moved_at_most = moved_at_most if moved else None  # for prepare, in this evaluation only
            try:
                self.calculate(atoms, ["forces"], system_changes)
            finally:
                self._moved_at_most = None
        view = self.results["forces"].view()
        view.flags.writeable = False
        return view

    def calculate(self, atoms=None, properties=("energy",), system_changes=all_changes):
        """The shared steps, then :meth:`evaluate` (class docstring): checks, dimension, list, results."""
        if atoms is not None:
            # ASE's copy is compared by positions, numbers, cell and pbc only: momenta and masses are not held
            # through the evaluation (32 bytes per particle) unless the forces depend on them
            self._take_snapshot(atoms, skip=() if self.velocity_dependent else ("momenta", "masses"))
        atoms = self.atoms
        if not self.conservative:
            refused = [name for name in properties if name in ENERGY_PROPERTIES]
            if refused:
                raise PropertyNotImplementedError(
                    f"{refused[0]} needs a conservative form: {self.non_conservative_reason()} is not a gradient "
                    "system (non-conservative forces; forces only)")
        dim = self.use_dim(atoms)  # not empty, finite, the dimension rule
        self.check_atoms(atoms, dim, properties)
        reach = self.cutoff(atoms, dim)
        cutoff, skin = (None, None) if reach is None else reach
        first = self._evaluations == 0
        r_pc, pbc = self.prepare(atoms, cutoff, skin, dim=dim)
        v_pc = None
        if self.velocity_dependent and atoms.has("momenta"):
            v_pc = atoms.get_velocities()
        state = EvaluationState(atoms=atoms, dim=dim, r_pc=r_pc, pbc=pbc, cell=atoms.cell.array,
                                nlist=None if cutoff is None else self.nlist, v_pc=v_pc, first=first)
        results = self.evaluate(state, properties)
        f_pc = results.get("forces")
        if f_pc is not None:
            f_pc[:, dim:] = 0.0
            if "forces" in properties:
                self.hint_force_scale(f_pc)
        if "energy" in results:
            results["free_energy"] = results["energy"]
        self.results.update(results)
