"""FIRE and LBFGS for SPH systems of 1e6 particles: ASE's algorithms, numba vector work (issue 33, item 1).

ASE's :class:`ase.optimize.FIRE` and :class:`ase.optimize.LBFGS` do their vector work in numpy
on ``3N`` coordinates (z too in 2D), with a fresh array for every intermediate, and ASE's run
loop asks for the forces three times per step. At 1e6 particles that made an LBFGS step cost
2.6x one force evaluation and a FIRE step 1.5x (issue 33). :class:`SPHFIRE` and
:class:`SPHLBFGS` are the same algorithms, step for step:

* :class:`ase.optimize.optimize.Optimizer` subclasses (``run``, ``irun``, ``attach``,
  ``trajectory``, ``logfile`` work as in ASE; ``restart`` files are not supported);
* vector work in numba loops over the ``dim * N`` coordinates that move: in 2D (an SPH
  calculator with ``dim = 2``) the z column is never read or written;
* buffers allocated once and reused between steps (fresh pages cost about 6x reused memory
  on these VMs); one force request per step (the calculator's cache serves the others);
* LBFGS: ``memory`` pairs ``(s, y)`` in float64, the pair of the next step kept in the slot of
  the pair that leaves the history, so ``memory`` pairs are all it holds (the step is formed in
  that slot too, which it leaves);
  three passes over them per step (the two-loop recursion on their dot products);
  ``s = x_{k+1} - x_k`` is taken from the positions the atoms have (constraints such as
  :class:`~ase_sphrelax.drivers.keep_inside.KeepInDomain` and observers included), as in ASE.

They reproduce ASE's trajectories to round-off (``tests/test_sph_optimizers.py``: 1e-9 on 2D
and 3D Fan cases, summation order being the only difference).
"""
from __future__ import annotations

import numba
import numpy as np
from ase import Atoms
from ase.optimize.optimize import DEFAULT_MAX_STEPS, Optimizer

from ..checks import ASE_DEFAULT_FMAX
from ..parallel import copy_rows, reduce_chunks, run_chunks
from .keep_inside import KeepInDomain
from .step_scale import warn_if_nothing_relaxed

__all__ = ["SPHFIRE", "SPHFIRE2", "SPHLBFGS", "moving_dim"]

_NOGIL = dict(nogil=True, cache=True)


# -- chunk loops: each works on particles [first, last) and adds its partial sums to out --------------
@numba.njit(**_NOGIL)
def _max_norm2(f_pc, d, out, first, last):
    best = out[0]
    for p in range(first, last):
        f2 = 0.0
        for c in range(d):
            f2 += f_pc[p, c] * f_pc[p, c]
        if not f2 <= best:  # NaN wins
            best = f2
    out[0] = best


# particles per block: the block's s, y, g (3 x 96 KB in 3D) stay in cache while every stored pair streams by in runs
# long enough for the prefetcher (the pair pass at 1e6 in 3D: 24-25 ms against 29 ms with blocks of 256)
_BLOCK = 4096


@numba.njit(**_NOGIL)
def _lbfgs_pair_dots(s_mpc, y_mpc, slot, x_pc, f_pc, d, out, first, last):
    """Complete the pending pair in ``slot`` (s = -x_k + x_{k+1}, y = F_k - F_{k+1}); then the dot
    products of s_slot, y_slot and g = -F with every stored s_j and y_j:
    out[6j..6j+5] += (s.s_j, s.y_j, y.s_j, y.y_j, g.s_j, g.y_j)."""
    m = s_mpc.shape[0]
    sf = s_mpc.reshape((m, -1))
    yf = y_mpc.reshape((m, -1))
    g = np.empty(_BLOCK * d)
    for b0 in range(first, last, _BLOCK):
        b1 = min(b0 + _BLOCK, last)
        e0 = b0 * d
        for p in range(b0, b1):
            for c in range(d):
                e = p * d + c
                sf[slot, e] = sf[slot, e] + x_pc[p, c]
                yf[slot, e] = yf[slot, e] - f_pc[p, c]
                g[e - e0] = -f_pc[p, c]
        e1 = b1 * d
        for j in range(m):
            a0 = a1 = a2 = a3 = a4 = a5 = 0.0
            for e in range(e0, e1):
                sj = sf[j, e]
                yj = yf[j, e]
                s = sf[slot, e]
                y = yf[slot, e]
                ge = g[e - e0]
                a0 += s * sj
                a1 += s * yj
                a2 += y * sj
                a3 += y * yj
                a4 += ge * sj
                a5 += ge * yj
            out[6 * j] += a0
            out[6 * j + 1] += a1
            out[6 * j + 2] += a2
            out[6 * j + 3] += a3
            out[6 * j + 4] += a4
            out[6 * j + 5] += a5


@numba.njit(**_NOGIL)
def _lbfgs_combine(f_pc, s_mpc, y_mpc, slot, cs, cy, cg, d, out, first, last):
    """z = cg g + sum_j cs_j s_j + cy_j y_j (g = -F) into s_slot, the oldest pair (read here for the
    last time: each block of z is formed aside, then written over its block of s_slot; an empty slot
    before the history is full); out[0] = max |z_p|^2."""
    m = s_mpc.shape[0]
    sf = s_mpc.reshape((m, -1))
    yf = y_mpc.reshape((m, -1))
    z = np.empty(_BLOCK * d)
    best = out[0]
    for b0 in range(first, last, _BLOCK):
        b1 = min(b0 + _BLOCK, last)
        e0 = b0 * d
        ne = (b1 - b0) * d
        for p in range(b0, b1):
            for c in range(d):
                z[p * d + c - e0] = cg * -f_pc[p, c]
        for j in range(m):
            a = cs[j]
            b = cy[j]
            if a == 0.0 and b == 0.0:
                continue
            s_j = sf[j, e0:e0 + ne]  # the block's slices, indexed from 0: the loop then vectorises
            y_j = yf[j, e0:e0 + ne]
            for k in range(ne):
                z[k] += a * s_j[k] + b * y_j[k]
        s_slot = sf[slot, e0:e0 + ne]
        for k in range(ne):
            s_slot[k] = z[k]
        for k in range(0, ne, d):
            z2 = 0.0
            for c in range(d):
                z2 += z[k + c] * z[k + c]
            if not z2 <= best:
                best = z2
    out[0] = best


@numba.njit(**_NOGIL)
def _lbfgs_finish(x_pc, f_pc, s_pc, y_pc, factor, scaled, damping, d, new_pc, in_place, first, last):
    """The step dr = -z (z in s_pc, :func:`_lbfgs_combine`; times factor when scaled) times damping;
    the next pending pair (s = -x_k over z, y = F_k) into its slot; the new positions x_k + dr into new_pc
    (which may be f_pc: each element of F is read before it is written), or with ``in_place`` into x_pc itself
    (the old positions are then -s)."""
    for p in range(first, last):
        for c in range(d):
            t = -s_pc[p, c]
            if scaled:
                t = t * factor
            t = t * damping
            x = x_pc[p, c]
            s_pc[p, c] = -x
            y_pc[p, c] = f_pc[p, c]
            if in_place:
                x_pc[p, c] = x + t
            else:
                new_pc[p, c] = x + t
        if not in_place:
            for c in range(d, 3):
                new_pc[p, c] = x_pc[p, c]


@numba.njit(**_NOGIL)
def _fire_dots(v_pc, f_pc, d, out, first, last):
    """``F . v``, ``F . F`` and ``v . v`` over ``[first, last)`` added to ``out[0:3]``: two partial sums each (even
    and odd particles), so that the adds of consecutive particles do not wait on each other."""
    vf0 = vf1 = ff0 = ff1 = vv0 = vv1 = 0.0
    p = first
    while p + 1 < last:
        for c in range(d):
            v = v_pc[p, c]
            f = f_pc[p, c]
            w = v_pc[p + 1, c]
            g = f_pc[p + 1, c]
            vf0 += v * f
            ff0 += f * f
            vv0 += v * v
            vf1 += w * g
            ff1 += g * g
            vv1 += w * w
        p += 2
    if p < last:
        for c in range(d):
            v = v_pc[p, c]
            f = f_pc[p, c]
            vf0 += v * f
            ff0 += f * f
            vv0 += v * v
    out[0] += vf0 + vf1
    out[1] += ff0 + ff1
    out[2] += vv0 + vv1


@numba.njit(**_NOGIL)
def _fire_move(x_pc, v_pc, f_pc, dt, scaled, maxstep, normdr, d, first, last):
    """New positions x + dt v (scaled to norm maxstep when scaled) into f_pc."""
    for p in range(first, last):
        for c in range(d):
            dr = dt * v_pc[p, c]
            if scaled:
                dr = maxstep * dr / normdr
            f_pc[p, c] = x_pc[p, c] + dr
        for c in range(d, 3):
            f_pc[p, c] = x_pc[p, c]


@numba.njit(**_NOGIL)
def _fire_velocity_move(x_pc, v_pc, f_pc, new_pc, mode, a, sqrt_ff, sqrt_vv, dt, scaled, maxstep, normdr, cap, d,
                        in_place, keep_old, out, first, last):
    """FIRE's new velocity (mode 0: v = 0, the first step; 1: FIRE's mixing; 2: v *= 0, uphill; then v += dt F) and
    the move x + dt v (scaled to norm maxstep when scaled, then each particle's move cut to length ``cap`` when
    ``cap > 0``) into ``new_pc``, in one pass: the norm of the whole move ``normdr`` is known before the pass
    (:func:`_fire_move_norm`). ``new_pc`` may be ``f_pc`` (each element of F is read before it is written).
    ``in_place``: the new positions go into ``x_pc`` itself, and with ``keep_old`` the old ones into ``new_pc``
    (without, ``new_pc`` is not written). ``out[0]``: the largest squared length of a particle's move so far (NaN
    wins)."""
    longest2 = out[0]
    for p in range(first, last):
        # the d <= 3 components in scalars, not a small array: 6 ms instead of 8 a pass at 1e6 in 2D
        f0 = f_pc[p, 0]
        f1 = f_pc[p, 1]
        f2 = f_pc[p, 2] if d == 3 else 0.0
        if mode == 0:
            v0 = v1 = v2 = 0.0
        elif mode == 1:
            v0 = (1.0 - a) * v_pc[p, 0] + a * f0 / sqrt_ff * sqrt_vv
            v1 = (1.0 - a) * v_pc[p, 1] + a * f1 / sqrt_ff * sqrt_vv
            v2 = (1.0 - a) * v_pc[p, 2] + a * f2 / sqrt_ff * sqrt_vv if d == 3 else 0.0
        else:
            v0 = v_pc[p, 0] * 0.0
            v1 = v_pc[p, 1] * 0.0
            v2 = v_pc[p, 2] * 0.0 if d == 3 else 0.0
        v0 = v0 + dt * f0
        v1 = v1 + dt * f1
        v_pc[p, 0] = v0
        v_pc[p, 1] = v1
        dr0 = dt * v0
        dr1 = dt * v1
        dr2 = 0.0
        if d == 3:
            v2 = v2 + dt * f2
            v_pc[p, 2] = v2
            dr2 = dt * v2
        if scaled:
            dr0 = maxstep * dr0 / normdr
            dr1 = maxstep * dr1 / normdr
            dr2 = maxstep * dr2 / normdr
        length2 = dr0 * dr0 + dr1 * dr1
        if d == 3:
            length2 += dr2 * dr2
        shrink = cap / np.sqrt(length2) if cap > 0.0 and length2 > cap * cap else 1.0
        x0 = x_pc[p, 0]
        x1 = x_pc[p, 1]
        x2 = x_pc[p, 2]
        m0 = x0 + dr0 * shrink  # times 1.0 (no cut): the move bit for bit
        m1 = x1 + dr1 * shrink
        m2 = x2 + dr2 * shrink if d == 3 else x2
        if in_place:
            if keep_old:
                new_pc[p, 0] = x0
                new_pc[p, 1] = x1
                new_pc[p, 2] = x2
            x_pc[p, 0] = m0
            x_pc[p, 1] = m1
            if d == 3:
                x_pc[p, 2] = m2
        else:
            new_pc[p, 0] = m0
            new_pc[p, 1] = m1
            new_pc[p, 2] = m2
        move2 = length2 * shrink * shrink
        if not move2 <= longest2:
            longest2 = move2
    out[0] = longest2


def _fire_move_norm(mode, a, sqrt_ff, sqrt_vv, vf, ff, vv, dt):
    """``|dt v'|`` of FIRE's new velocity ``v'`` (:func:`_fire_velocity_move`) from the sums of F.v, F.F and v.v:
    ``v' = (1 - a) v + b F`` with ``b = a |v| / |F| + dt`` (mode 1; F.v > 0, so |F| > 0 and every term is positive),
    or ``dt F`` (modes 0 and 2: the first step, an uphill one)."""
    if mode != 1:
        return dt * dt * sqrt_ff
    b = a * sqrt_vv / sqrt_ff + dt
    v2 = (1.0 - a) ** 2 * vv + 2.0 * (1.0 - a) * b * vf + b * b * ff
    return dt * float(np.sqrt(max(v2, 0.0)))


@numba.njit(**_NOGIL)
def _fire2_back(x_pc, v_pc, half_dt, d, new_pc, first, last):
    """FIRE2's correction after an uphill step: new positions x - dt v / 2 into new_pc."""
    for p in range(first, last):
        for c in range(d):
            new_pc[p, c] = x_pc[p, c] + half_dt * v_pc[p, c]  # half_dt = -dt / 2 (ASE: r + (-0.5 dt) v)
        for c in range(d, 3):
            new_pc[p, c] = x_pc[p, c]


@numba.njit(**_NOGIL)
def _fire2_velocity(v_pc, f_pc, fresh, a, scale, dt, d, out, first, last):
    """FIRE2's semi-implicit Euler and mixing: v = (1 - a)(v + dt F) + scale F (v = 0 first when
    ``fresh``; scale = a |v + dt F| / |F|); out += |dt v|^2."""
    acc = 0.0
    for p in range(first, last):
        for c in range(d):
            f = f_pc[p, c]
            v = 0.0 if fresh else v_pc[p, c]
            v = (1.0 - a) * (v + dt * f) + scale * f
            v_pc[p, c] = v
            dr = dt * v
            acc += dr * dr
    out[0] += acc


def _sum(outs, k=0):
    return float(sum(o[k] for o in outs))


def _max(outs, k):
    return float(max(o[k] for o in outs))


def _longer(a, b):
    """The larger of two move lengths, None when either is unknown."""
    return None if a is None or b is None else max(a, b)


def moving_dim(atoms, dim):
    """The coordinates an optimiser moves: 2 for an SPH calculator in 2D (or ``dim=2``), else 3; ``dim`` other
    than None, 2 or 3 is refused."""
    if dim is None:
        calc = getattr(atoms, "calc", None)
        dim = getattr(calc, "dim", None) or (getattr(calc, "parameters", None) or {}).get("dim")
        return 2 if dim == 2 else 3
    if isinstance(dim, bool) or dim not in (2, 3):
        raise ValueError(f"dim must be None, 2 or 3, got {dim!r}")
    return int(dim)


class _SPHOptimizer(Optimizer):
    """Shared run loop and coordinate access of :class:`SPHFIRE` and :class:`SPHLBFGS`.

    With an :class:`ase.Atoms` the step reads ``atoms.positions`` in place and the forces in place too (the SPH
    calculator's ``forces_view``, when the only constraints are
    :class:`~ase_sphrelax.drivers.keep_inside.KeepInDomain`). SPHFIRE and SPHLBFGS then write their new positions
    into ``atoms.positions`` itself and keep the old ones for the constraint (SPHFIRE in a buffer of its own,
    SPHLBFGS as ``-s`` of the pending pair): the result of ``Atoms.set_positions`` (the constraints' adjustment, a
    copy in place), without the copy. Otherwise (FIRE2, other constraints) the new positions are formed in a buffer
    (or the step's own force array), go through the constraints (``adjust_positions``) and are copied into
    ``atoms.positions``. KeepInDomain is told the step's longest move and, from the calculator
    (``wall_candidates``), which particles can be near the wall: it tests those alone when the moves are short
    (:meth:`~ase_sphrelax.drivers.keep_inside.KeepInDomain.adjust_moved`). After a step the force request does
    not compare the positions the step has just set (``forces_view(moved=True)``). Any other optimizable (a
    Filter) goes through ASE's ``get_x`` / ``get_gradient`` / ``set_x`` on all 3 coordinates.
    """

    def __init__(self, atoms, restart=None, logfile="-", trajectory=None, dim=None, **kwargs):
        if restart is not None:
            raise ValueError(f"restart: {type(self).__name__} keeps no restart file, got {restart!r}")
        self._fast = isinstance(atoms, Atoms)
        self._dim_arg = moving_dim(atoms, dim) if dim is not None else None
        self.dim = None  # resolved at the first step (the SPH calculator knows it after an evaluation)
        self._silent = logfile is None  # ASE computes E and |F| for a log that writes nothing
        # the step's forces came from the calculator at the atoms' positions (not given to step()): its last evaluation
        # was at the step's start (_wall_hint)
        self._forces_current = False
        self._last_move = None  # the longest move of a particle in the last step, when known (_forces)
        Optimizer.__init__(self, atoms, restart=None, logfile=logfile, trajectory=trajectory, **kwargs)

    def read(self):
        raise ValueError(f"restart: {type(self).__name__} keeps no restart file")

    # -- coordinates ---------------------------------------------------------------------------
    def _forces(self, writable=True, moved=False, only_positions=False):
        """Forces (n, 3), constraints applied: a fresh writable array, or with ``writable=False`` the SPH
        calculator's own result, read only (:meth:`~ase_sphrelax.calculators.base.SPHCalculator.forces_view`: no
        copy of N forces per step), when the only constraints are :class:`KeepInDomain` (which leave forces alone).
        ``moved``: this optimiser's step has just set the positions (the calculator need not compare them), each
        particle's move at most :attr:`_last_move` when known (the calculator's neighbour list need not measure
        them while their sum since its build stays under half its skin). ``only_positions``: no other code ran since
        the calculator's last evaluation (``run`` without observers): only the positions can have changed."""
        bound = self._last_move if moved else None
        self._last_move = None  # a bound for this request only
        if self._fast:
            atoms = self.optimizable.atoms
            if not writable and hasattr(atoms.calc, "forces_view") \
                    and all(isinstance(c, KeepInDomain) for c in atoms.constraints):
                return atoms.calc.forces_view(atoms, moved=moved, moved_at_most=bound, only_positions=only_positions)
            return atoms.get_forces()
        return -self.optimizable.get_gradient().reshape(-1, 3)

    def _scratch_like(self, f_pc):
        """Where a step writes the new positions: ``f_pc`` itself when it is the step's own copy (writable), else
        an (n, 3) array of this optimiser, allocated once and kept between steps."""
        if f_pc.flags.writeable:
            return f_pc
        buffer = getattr(self, "_new_pc", None)
        if buffer is None or buffer.shape != f_pc.shape:
            buffer = self._new_pc = np.empty(f_pc.shape)
        return buffer

    def _positions(self):
        """Positions (n, 3), read only."""
        if self._fast:
            return self.optimizable.atoms.positions
        return self.optimizable.get_x().reshape(-1, 3)

    def _set_positions(self, new_pc, longest=None):
        """Set positions from ``new_pc`` (n, 3), which the constraints may change in place; ``longest``: the
        longest move of a particle in this update (None: not known), for :class:`KeepInDomain`'s test."""
        if self._fast:
            atoms = self.optimizable.atoms
            for constraint in atoms.constraints:  # as Atoms.set_positions, without its copy
                if isinstance(constraint, KeepInDomain):
                    longest = _longer(longest, constraint.adjust_moved(atoms.positions, new_pc,
                                                                       **self._wall_hint(constraint, longest)))
                else:
                    constraint.adjust_positions(atoms, new_pc)
                    longest = None  # another constraint's moves are not known
            self._last_move = longest
            positions = atoms.arrays["positions"]
            if positions.shape == new_pc.shape and positions.dtype == new_pc.dtype == np.float64:
                copy_rows(positions, new_pc)  # ASE's set_positions copies in place too, on one thread
            else:
                atoms.set_positions(new_pc, apply_constraint=False)
        else:
            self.optimizable.set_x(new_pc.reshape(-1))

    def _moves_in_place(self, x_pc):
        """Whether a step may write its new positions into ``x_pc`` = ``atoms.positions`` itself (the old ones aside,
        :meth:`_constrain_moved`): an Atoms whose constraints are :class:`KeepInDomain` only (or none), its positions
        float64, C-contiguous and writeable. The result is that of :meth:`_set_positions`, without its copy."""
        if not self._fast:
            return False
        atoms = self.optimizable.atoms
        positions = atoms.arrays["positions"]
        return x_pc is positions and positions.dtype == np.float64 and positions.flags.c_contiguous \
            and positions.flags.writeable and all(isinstance(c, KeepInDomain) for c in atoms.constraints)

    def _constrain_moved(self, old_pc, longest):
        """The constraints of a step that moved ``atoms.positions`` in place from ``old_pc`` (:meth:`_moves_in_place`;
        each particle's move at most ``longest``; ``old_pc`` an array or a function of indices, as
        :meth:`KeepInDomain.adjust_moved` takes it)."""
        atoms = self.optimizable.atoms
        for constraint in atoms.constraints:
            longest = _longer(longest, constraint.adjust_moved(old_pc, atoms.arrays["positions"],
                                                               **self._wall_hint(constraint, longest)))
        self._last_move = longest

    def _wall_hint(self, constraint, longest):
        """:meth:`KeepInDomain.adjust_moved`'s keywords: the longest move and, when the calculator knows them for the
        positions of its last evaluation (the step's start: the step's forces came from it,
        :attr:`_forces_current`), the particles that can be near the wall (``wall_candidates``)."""
        hint = dict(longest=longest)
        if longest is None or not self._forces_current:
            return hint
        known = getattr(self.optimizable.atoms.calc, "wall_candidates", None)
        found = known(constraint.domain) if known is not None else None
        if found is not None:
            hint.update(candidates=found[0], margin=found[1], candidates_phi=found[2])
        return hint

    def _setup_dim(self):
        if self.dim is None:
            self.dim = self._dim_arg or (moving_dim(self.optimizable.atoms, None) if self._fast else 3)
        return self.dim

    # -- the run loop: one force request per step -----------------------------------------------
    def run(self, fmax=ASE_DEFAULT_FMAX, steps=DEFAULT_MAX_STEPS):
        """Run until ``max |F| < fmax`` or ``steps`` steps (as :meth:`ase.optimize.optimize.Optimizer.run`).

        Warns (:class:`~ase_sphrelax.drivers.step_scale.NothingRelaxedWarning`) when ``fmax > 0``
        stopped it at step 0.
        """
        converged = False
        self.fmax = fmax
        for converged in self._irun(steps, reuse=True):
            pass
        warn_if_nothing_relaxed(self, fmax, converged)
        return converged

    def irun(self, fmax=0.05, steps=DEFAULT_MAX_STEPS):
        """Generator of :meth:`run`, yielding ``converged`` after each step (as ASE's)."""
        self.fmax = fmax
        return self._irun(steps)

    def _irun(self, steps, reuse=False):
        self.max_steps = self.nsteps + steps
        f_pc = self._forces(writable=False)
        if self.nsteps == 0:
            self.log(-f_pc.reshape(-1) if not self._silent else None)
            if self.trajectory is None or self._traj_is_empty():
                self.call_observers()
        is_converged = self._converged(f_pc)
        yield is_converged
        while not is_converged and self.nsteps < self.max_steps:
            # an observer or the caller may have moved the atoms: then the step asks anew (cached)
            step_f, f_pc = (f_pc if reuse and not self.observers else None), None
            self._forces_current = True  # the forces above, at these positions, or asked anew by the step
            self._last_move = None  # set by a step that knows its moves (SPHFIRE, SPHLBFGS)
            self._step(step_f)
            step_f = None
            self.nsteps += 1
            # run without observers: nothing but this step touched the atoms since the last evaluation
            f_pc = self._forces(writable=False, moved=True, only_positions=reuse and not self.observers)
            self.log(-f_pc.reshape(-1) if not self._silent else None)
            self.call_observers()
            is_converged = self._converged(f_pc)
            yield is_converged

    def _converged(self, f_pc):
        if self.fmax is None or self.fmax <= 0.0:
            return False
        outs = reduce_chunks(_max_norm2, len(f_pc), (f_pc, 3), 1)
        return bool(np.sqrt(_max(outs, 0)) < self.fmax)

    def gradient_converged(self, gradient):
        if self.fmax is not None and self.fmax <= 0.0:
            return False
        return Optimizer.gradient_converged(self, gradient)

    def log(self, gradient):
        if not self._silent:
            Optimizer.log(self, gradient)

    def step(self, forces=None):
        """One step from ``forces`` ((N, 3); None: asked from the calculator)."""
        if forces is not None:
            forces = np.array(forces, dtype=float).reshape(-1, 3)
        self._forces_current = forces is None
        self._step(forces)

    def _step(self, f_pc=None):  # pragma: no cover - defined by the subclasses
        raise NotImplementedError


def _check_positive_finite(**values):
    """ValueError naming the first of ``values`` that is not a positive finite number (before any work)."""
    for name, value in values.items():
        if not (isinstance(value, (int, float, np.floating)) and np.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be a positive finite number, got {value!r}")


def _set_fire_step(opt, dt, maxstep, max_particle_step=None):
    """FIRE's and FIRE2's time step, step counter, step cap (``maxstep`` None: the optimiser's default) and cut of
    each particle's move (``max_particle_step`` None: none)."""
    opt.dt = float(dt)
    opt.Nsteps = 0
    opt.maxstep = opt.defaults["maxstep"] if maxstep is None else float(maxstep)
    if not opt.maxstep > 0:
        raise ValueError(f"maxstep must be positive, got {maxstep!r}")
    if max_particle_step is not None:
        _check_positive_finite(max_particle_step=max_particle_step)
        max_particle_step = float(max_particle_step)
    opt.max_particle_step = max_particle_step


class _FIREBase(_SPHOptimizer):
    """What FIRE and FIRE2 share: the velocity reset, the step's inputs, FIRE2's move ``x += dt v`` capped at
    ``maxstep`` (the velocity update's partial sums ``outs`` of |dt v|^2 give its length; SPHFIRE moves in the pass of
    its velocity update, with its cut of each particle's move) and ``todict``."""

    def initialize(self):
        self.vel = None

    def _start_step(self, f_pc):
        """The step's forces (asked for when not given), positions, moving dimensions and particle count."""
        f_pc = self._forces(writable=False) if f_pc is None else f_pc
        return f_pc, self._positions(), self._setup_dim(), len(f_pc)

    def _move(self, outs, x_pc, f_pc, n, d):
        normdr = float(np.sqrt(_sum(outs)))
        scaled = normdr > self.maxstep
        new_pc = self._scratch_like(f_pc)
        run_chunks(_fire_move, n, (x_pc, self.vel, new_pc, self.dt, scaled, self.maxstep, normdr, d))
        self._set_positions(new_pc)

    def todict(self):
        description = Optimizer.todict(self)
        description.update(dt=self.dt, dim=self.dim, max_particle_step=self.max_particle_step)
        return description


class SPHFIRE(_FIREBase):
    """ASE's FIRE (Bitzek et al. 2006, as :class:`ase.optimize.FIRE`) with numba vector work.

    Per step two passes over the ``dim * N`` coordinates that move: one for ``F . v``, ``F . F`` and ``v . v``, one
    for the new velocity and the move, whose norm (for ``maxstep``'s cap) follows from the first pass's sums.

    Parameters
    ----------
    atoms : Atoms or Filter
        With a calculator.
    dt, maxstep, dtmax, Nmin, finc, fdec, astart, fa, a : float
        As :class:`ase.optimize.FIRE` (``maxstep`` caps the norm of the whole step, as ASE's).
    dim : None, 2 or 3
        Coordinates that move: None takes 2 from an SPH calculator in 2D, else 3.
    max_particle_step : float or None
        Each particle's move in one step is cut to at most this length (after ``maxstep``'s cut of the whole
        step; its velocity is kept). Only the particles that would move further are cut, where LAMMPS's
        ``min_modify dmax`` shortens the time step of all. None (default): no cut, ASE's step.
    logfile, trajectory, **kwargs
        As :class:`ase.optimize.optimize.Optimizer` (``restart`` is refused).
    """

    def __init__(self, atoms, restart=None, logfile="-", trajectory=None, dt=0.1, maxstep=None, dtmax=1.0, Nmin=5,
                 finc=1.1, fdec=0.5, astart=0.1, fa=0.99, a=0.1, dim=None,
                 max_particle_step=None, **kwargs):
        _check_positive_finite(dt=dt, dtmax=dtmax, finc=finc, fdec=fdec, fa=fa)
        _SPHOptimizer.__init__(self, atoms, restart=restart, logfile=logfile, trajectory=trajectory, dim=dim,
                               **kwargs)
        _set_fire_step(self, dt, maxstep, max_particle_step)
        self.dtmax, self.Nmin, self.finc, self.fdec = float(dtmax), Nmin, float(finc), float(fdec)
        self.astart, self.fa, self.a = float(astart), float(fa), float(a)

    def _step(self, f_pc=None):
        f_pc, x_pc, d, n = self._start_step(f_pc)
        fresh = self.vel is None
        if fresh:
            self.vel = np.zeros((n, d))
        elif self.vel.shape[0] != n:
            raise ValueError(f"atoms: the number of particles changed from {self.vel.shape[0]} to {n}")
        outs = reduce_chunks(_fire_dots, n, (self.vel, f_pc, d), 3)
        vf, ff, vv = _sum(outs, 0), _sum(outs, 1), _sum(outs, 2)
        sqrt_ff, sqrt_vv = float(np.sqrt(ff)), float(np.sqrt(vv))
        mode = 0 if fresh else (1 if vf > 0.0 else 2)
        a_mix = self.a  # the mixing uses a before its update, v += dt F the updated dt (as ASE)
        if mode == 1:
            if self.Nsteps > self.Nmin:
                self.dt = min(self.dt * self.finc, self.dtmax)
                self.a *= self.fa
            self.Nsteps += 1
        elif mode == 2:
            self.a = self.astart
            self.dt *= self.fdec
            self.Nsteps = 0
        # the new velocity and the move in one pass: the move's norm from the sums above
        normdr = _fire_move_norm(mode, a_mix, sqrt_ff, sqrt_vv, vf, ff, vv, self.dt)
        scaled = normdr > self.maxstep
        # the new positions into atoms.positions itself and the old ones aside (no copy), when the constraints allow;
        # with the cut of each move, only the old positions of the particles that can leave the domain
        in_place = self._moves_in_place(x_pc)
        cap = 0.0 if self.max_particle_step is None else self.max_particle_step
        may_leave = self._may_leave(cap) if in_place else None
        new_pc = x_pc if may_leave is not None else self._scratch_like(f_pc)
        old_kept = None if may_leave is None else np.take(x_pc, may_leave, axis=0)
        outs = reduce_chunks(_fire_velocity_move, n, (x_pc, self.vel, f_pc, new_pc, mode, a_mix, sqrt_ff, sqrt_vv,
                                                      self.dt, scaled, self.maxstep, normdr, cap, d, in_place,
                                                      may_leave is None), 1)
        longest = float(np.sqrt(_max(outs, 0)))
        if not in_place:
            self._set_positions(new_pc, longest)
        elif may_leave is None:
            self._constrain_moved(new_pc, longest)
        else:
            def old_rows(out):  # the old positions of the particles ``out``, all among ``may_leave``
                rows = np.searchsorted(may_leave, out)
                if np.any(rows >= len(may_leave)) or np.any(may_leave[np.minimum(rows, len(may_leave) - 1)] != out):
                    raise RuntimeError("SPHFIRE: a particle left the domain that the step's cut should have kept in")
                return old_kept[rows]

            self._constrain_moved(old_rows, longest)

    def _may_leave(self, cap):
        """The sorted indices of the only particles that a step whose moves are cut at ``cap`` can take out of the
        domains of the constraints (KeepInDomain's, :meth:`KeepInDomain.may_leave` with the calculator's
        ``wall_candidates`` at the step's start); None when not known."""
        if not cap > 0.0:
            return None
        bound = cap * (1.0 + 1e-9)  # the round-off of a move cut at cap
        parts = []
        for constraint in self.optimizable.atoms.constraints:
            part = constraint.may_leave(**self._wall_hint(constraint, bound))
            if part is None:
                return None
            parts.append(part)
        return np.unique(np.concatenate(parts)) if parts else np.zeros(0, dtype=np.intp)


class SPHFIRE2(_FIREBase):
    """ASE's FIRE2 (Guénolé et al. 2020, as :class:`ase.optimize.fire2.FIRE2`) with numba vector work.

    FIRE (Bitzek et al. 2006) with the changes of Guénolé et al. (2020, Comput. Mater. Sci. 175,
    109584, Algorithm 2): semi-implicit Euler (``v += dt F`` before the mixing
    ``v = (1 - a) v + a |v| F / |F|``, their Eq. 6-7), ``dt`` never below ``dtmin``, and after an
    uphill step (``F . v <= 0``) the correction ``x -= dt v / 2`` then ``v = 0``: the particles go back
    half the step that overshot and the step continues from the forces there, a second force
    evaluation in that step (as ASE's; ``calc.evaluations`` counts it). ABC-FIRE (``use_abc``) and
    ``position_reset_callback`` are not supported.

    Per step: one pass for ``F . v``, ``F . F``, ``v . v``; after an uphill step one pass for the
    correction and one for ``F . F`` at the corrected positions; one pass for the velocity (whose
    norm ``|v + dt F|`` is ``sqrt(v.v + 2 dt F.v + dt^2 F.F)`` from the first pass's sums) and one
    for the move, on the ``dim * N`` coordinates that move.

    Parameters
    ----------
    atoms : Atoms or Filter
        With a calculator.
    dt, maxstep, dtmax, dtmin, Nmin, finc, fdec, astart, fa : float
        As :class:`ase.optimize.fire2.FIRE2` (``maxstep`` caps the norm of the whole step, as ASE's).
    dim : None, 2 or 3
        Coordinates that move: None takes 2 from an SPH calculator in 2D, else 3.
    logfile, trajectory, **kwargs
        As :class:`ase.optimize.optimize.Optimizer` (``restart`` is refused).
    """

    def __init__(self, atoms, restart=None, logfile="-", trajectory=None, dt=0.1, maxstep=None, dtmax=1.0,
                 dtmin=2e-3, Nmin=20, finc=1.1, fdec=0.5, astart=0.25, fa=0.99, dim=None, **kwargs):
        _check_positive_finite(dt=dt, dtmax=dtmax, dtmin=dtmin, finc=finc, fdec=fdec, fa=fa)
        _SPHOptimizer.__init__(self, atoms, restart=restart, logfile=logfile, trajectory=trajectory, dim=dim,
                               **kwargs)
        _set_fire_step(self, dt, maxstep)  # no cut of a particle's move: its uphill correction goes back dt v / 2
        self.dtmax, self.dtmin, self.Nmin = float(dtmax), float(dtmin), Nmin
        self.finc, self.fdec, self.astart, self.fa = float(finc), float(fdec), float(astart), float(fa)
        self.a = self.astart

    def _step(self, f_pc=None):
        f_pc, x_pc, d, n = self._start_step(f_pc)
        fresh = self.vel is None
        if fresh:
            self.vel = np.zeros((n, d))
            vf = vv = 0.0
            ff = _sum(reduce_chunks(_fire_dots, n, (self.vel, f_pc, d), 3), 1)
        else:
            if self.vel.shape[0] != n:
                raise ValueError(f"atoms: the number of particles changed from {self.vel.shape[0]} to {n}")
            outs = reduce_chunks(_fire_dots, n, (self.vel, f_pc, d), 3)
            vf, ff, vv = _sum(outs, 0), _sum(outs, 1), _sum(outs, 2)
            if vf > 0.0:
                self.Nsteps += 1
                if self.Nsteps > self.Nmin:
                    self.dt = min(self.dt * self.finc, self.dtmax)
                    self.a *= self.fa
            else:
                self.Nsteps = 0
                self.dt = max(self.dt * self.fdec, self.dtmin)
                self.a = self.astart
                # back half the step that went uphill, then the forces there
                back_pc = self._scratch_like(f_pc)
                run_chunks(_fire2_back, n, (x_pc, self.vel, -0.5 * self.dt, d, back_pc))
                self._set_positions(back_pc)
                f_pc, x_pc = self._forces(writable=False), self._positions()
                fresh, vf, vv = True, 0.0, 0.0  # v = 0
                ff = _sum(reduce_chunks(_fire_dots, n, (self.vel, f_pc, d), 3), 1)
        # |v + dt F| from the sums, then the mixing's coefficient of F
        norm_v = float(np.sqrt(max(vv + 2.0 * self.dt * vf + self.dt * self.dt * ff, 0.0)))
        scale = self.a * norm_v / np.sqrt(ff) if ff > 0.0 else 0.0
        outs = reduce_chunks(_fire2_velocity, n, (self.vel, f_pc, fresh, self.a, scale, self.dt, d), 1)
        self._move(outs, x_pc, f_pc, n, d)


class SPHLBFGS(_SPHOptimizer):
    """ASE's LBFGS (as :class:`ase.optimize.LBFGS`, no line search) with numba vector work.

    The two-loop recursion (Nocedal 1980) over the last ``memory`` pairs
    ``s_k = x_{k+1} - x_k``, ``y_k = g_{k+1} - g_k`` with ``H0 = 1 / alpha``; the step is
    scaled so that no particle moves more than ``maxstep`` (ASE's ``determine_step``), then
    multiplied by ``damping``. The recursion runs on the coefficients of the step in the basis
    ``(s_j, y_j, g)`` from the matrix of their dot products, as in the vector-free L-BFGS of
    Chen et al. (NeurIPS 2014): one pass completes the newest pair and takes its dot products
    (and g's) with every stored pair, one pass forms the step, one moves the particles, where
    ASE's recursion makes ``2 memory + 1`` passes. The same arithmetic up to round-off.
    Memory: ``2 memory`` vectors of ``dim * N`` floats (the step is formed in the slot of the
    pair that leaves the history).

    Parameters
    ----------
    atoms : Atoms or Filter
        With a calculator.
    maxstep, memory, damping, alpha : float, int, float, float
        As :class:`ase.optimize.LBFGS` (any positive ``maxstep``: SPH lengths have no Angstrom scale).
    dim : None, 2 or 3
        Coordinates that move: None takes 2 from an SPH calculator in 2D, else 3.
    logfile, trajectory, **kwargs
        As :class:`ase.optimize.optimize.Optimizer` (``restart`` is refused).
    """

    def __init__(self, atoms, restart=None, logfile="-", trajectory=None, maxstep=None, memory=100, damping=1.0,
                 alpha=70.0, dim=None, **kwargs):
        if isinstance(memory, bool) or not isinstance(memory, (int, np.integer)) or memory < 1:
            raise ValueError(f"memory must be an integer >= 1, got {memory!r}")
        for name, value in dict(damping=damping, alpha=alpha).items():
            if not (isinstance(value, (int, float, np.floating)) and np.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive finite number, got {value!r}")
        self.memory = int(memory)
        _SPHOptimizer.__init__(self, atoms, restart=restart, logfile=logfile, trajectory=trajectory, dim=dim,
                               **kwargs)
        self.maxstep = self.defaults["maxstep"] if maxstep is None else maxstep
        if not (isinstance(self.maxstep, (int, float, np.floating)) and self.maxstep > 0):
            raise ValueError(f"maxstep must be positive, got {maxstep!r}")
        self.damping, self.alpha = float(damping), float(alpha)

    def initialize(self):
        self.iteration = 0  # steps taken (ASE: state.iteration)
        self._s = self._y = None
        self._rho = np.zeros(self.memory)

    def _buffers(self, n, d):
        if self._s is None:
            self._s = np.zeros((self.memory, n, d))
            self._y = np.zeros((self.memory, n, d))
            self._ss, self._sy, self._yy = (np.zeros((self.memory, self.memory)) for _ in range(3))
        elif self._s.shape[1] != n:
            raise ValueError(f"atoms: the number of particles changed from {self._s.shape[1]} to {n}")

    def _step(self, f_pc=None):
        f_pc = self._forces(writable=False) if f_pc is None else f_pc  # read only (the calculator's, no copy)
        x_pc = self._positions()
        d = self._setup_dim()
        n, m, k = len(f_pc), self.memory, self.iteration
        self._buffers(n, d)
        s, y, rho = self._s, self._y, self._rho
        h0 = 1.0 / self.alpha
        count = min(m, k)
        cs, cy = np.zeros(m), np.zeros(m)
        if count == 0:
            cg = h0  # ASE: z = H0 @ g
        else:
            # the pair of the last step, from the positions and forces the atoms have now, and every
            # dot product the two-loop recursion needs, in one pass (g = -F changes every step)
            p = (k - 1) % m
            dots = np.sum(reduce_chunks(_lbfgs_pair_dots, n, (s, y, p, x_pc, f_pc, d), 6 * m), axis=0).reshape(m, 6)
            ss, sy, yy = self._ss, self._sy, self._yy
            ss[p, :] = ss[:, p] = dots[:, 0]
            sy[p, :] = dots[:, 1]  # s_p . y_j
            sy[:, p] = dots[:, 2]  # s_j . y_p
            yy[p, :] = yy[:, p] = dots[:, 3]
            gs, gy = dots[:, 4], dots[:, 5]
            rho[p] = 1.0 / sy[p, p]
            # the two-loop recursion (Nocedal 1980) on the coefficients of z = cg g + sum cs_j s_j + cy_j y_j
            slots = [(k - count + i) % m for i in range(count)]  # oldest first
            a = np.empty(count)
            cg = 1.0
            for i in range(count - 1, -1, -1):
                j = slots[i]
                a[i] = rho[j] * (cs @ ss[j] + cy @ sy[j] + cg * gs[j])  # rho_i s_i . q
                cy[j] -= a[i]
            cs *= h0
            cy *= h0
            cg *= h0
            for i in range(count):
                j = slots[i]
                b = rho[j] * (cs @ sy[:, j] + cy @ yy[j] + cg * gy[j])  # rho_i y_i . z
                cs[j] += a[i] - b
        slot = k % m  # the oldest pair (its last use is in z) holds z, then the pending pair of this step
        outs = reduce_chunks(_lbfgs_combine, n, (f_pc, s, y, slot, cs, cy, cg, d), 1)
        longest = float(np.sqrt(_max(outs, 0)))  # ASE: the largest per-particle norm of the step
        scaled = longest >= self.maxstep
        factor = self.maxstep / longest if scaled else 1.0
        # the new positions into atoms.positions itself when the constraints allow (the old ones are -s[slot])
        in_place = self._moves_in_place(x_pc)
        new_pc = x_pc if in_place else self._scratch_like(f_pc)
        run_chunks(_lbfgs_finish, n, (x_pc, f_pc, s[slot], y[slot], factor, scaled, self.damping, d, new_pc, in_place))
        self.iteration += 1
        moved = longest * factor * self.damping
        if not in_place:
            self._set_positions(new_pc, moved)
            return
        positions, s_slot = x_pc, s[slot]

        def old_rows(out):  # the old positions of the particles ``out``: -s, z (2D) as it is
            rows = np.array(positions[out])
            rows[:, :d] = -s_slot[out]
            return rows

        self._constrain_moved(old_rows, moved)

    def todict(self):
        description = Optimizer.todict(self)
        description.update(memory=self.memory, damping=self.damping, alpha=self.alpha, dim=self.dim)
        return description
