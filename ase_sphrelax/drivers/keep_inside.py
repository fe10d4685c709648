"""An ASE constraint that keeps particles inside a bounded domain (issue 10 item 9).

Fan's boundary term (Eq. 3.8, force Eq. 4.4) pulls a particle that left the domain back,
but an optimiser step can be longer than the term's reach: quasi-Newton and FIRE steps
grow up to ``10 c h`` (:func:`~ase_sphrelax.drivers.make_optimizer`), and near the sharp
corners and thin features of CSG domains the level set's normal turns abruptly. Measured:
a ``Difference`` domain relaxed with LBFGS ended with 2 particles outside.

:class:`KeepInDomain` is applied by ASE to every position update of every optimiser
(``atoms.set_positions`` applies constraints): a step that would take a particle from inside
to outside is cut at half of its way to the boundary (bisection on the level set along the
step); a particle that is already outside is moved along ``-grad phi`` back inside. Nothing
is hidden: ``n_returned`` counts the corrected particle moves, ``n_left_outside`` the
particles that the last update could not bring inside (the run reports both).
:func:`~ase_sphrelax.drivers.make_optimizer` and :class:`~ase_sphrelax.drivers.FanRelaxation`
attach it when the calculator has a domain (``keep_inside=True``, the default).
"""
from __future__ import annotations

import numpy as np

__all__ = ["KeepInDomain", "attach_keep_inside", "calculator_domain"]

_BISECTIONS = 40
_PROJECTIONS = 8
_CHUNK = 1 << 16  # particles per level-set call of the first test (no level set of all N held at once)


def calculator_domain(atoms):
    """The ``domain`` parameter of the calculator of ``atoms`` (or of a Filter's atoms), or None."""
    calc = getattr(atoms, "calc", None)
    if calc is None and hasattr(atoms, "atoms"):
        calc = getattr(atoms.atoms, "calc", None)
    params = getattr(calc, "parameters", {}) or {}
    return params.get("domain")


class KeepInDomain:
    """ASE constraint: no position update takes a particle out of ``domain``.

    Parameters
    ----------
    domain : Domain
        A level set with ``phi`` and ``phi_and_normal`` (negative inside) and ``dim``.

    Attributes
    ----------
    n_returned : int
        Particle moves corrected so far (steps cut, or particles moved back inside).
    n_left_outside : int
        Particles still outside after the last update (0 unless the level set's normal
        does not lead inside, e.g. at a particle far outside a non-convex CSG domain).
    """

    def __init__(self, domain):
        if not (hasattr(domain, "phi") and hasattr(domain, "phi_and_normal") and hasattr(domain, "dim")):
            raise TypeError(f"domain must be a Domain with phi(), phi_and_normal() and dim, got {type(domain).__name__}")
        from ..domains.base import Domain  # here: importing the drivers (sphrelax --help) loads no domain

        self.domain = domain
        self._takes_positions = isinstance(domain, Domain)  # a Domain takes (P, 3) positions itself
        self.n_returned = 0
        self.n_left_outside = 0

    def _phi(self, r_pc):
        if not self._takes_positions:  # a duck-typed level set gets (P, dim) points
            r_pc = np.ascontiguousarray(r_pc[:, : self.domain.dim])
        return np.asarray(self.domain.phi(r_pc), dtype=float).reshape(-1)

    def adjust_positions(self, atoms, new):
        """Cut the steps that leave the domain; move particles that are outside back in (in place)."""
        self.adjust_moved(np.asarray(atoms.positions, dtype=float), new)

    def adjust_moved(self, old_pc, new, longest=None, candidates=None, margin=None, candidates_phi=None):
        """:meth:`adjust_positions` for a move from ``old_pc`` to ``new`` (``new`` may be the Atoms' positions array,
        moved in place by an optimiser step; it is changed in place). ``old_pc``: an array (N, 3), or a function of
        the indices of the particles that left giving their old positions (k, 3) (an optimiser that holds them in
        another form, SPHLBFGS's ``-s``).

        ``candidates`` and ``margin`` (both or neither): every particle not in ``candidates`` lies at least ``margin``
        inside the domain at ``old_pc`` (an SPH calculator's ``wall_candidates`` for the positions of its last
        evaluation). When every move is shorter than half the margin (``longest``, the longest move of a particle) only
        the candidates can have left (the level set of a :class:`~ase_sphrelax.domains.base.Domain` is a signed
        distance: it changes by at most the move; half: an interpolated table's slope may exceed 1 a little), and only
        they are tested: the same particles are found as by testing all (at 1e6 particles in 3D the level set of all of
        them cost 5 ms a step). ``candidates_phi``: the level set of each candidate at ``old_pc``; then only the
        candidates with ``phi > -2 longest`` (or NaN) are tested, by the same rule.

        Returns the longest move from ``old_pc`` of the particles it changed (0.0 when none; a step cut at the
        boundary is shorter than the step, a particle moved back from outside can move further)."""
        tested = self.may_leave(longest, candidates, margin, candidates_phi)
        out = self._outside(new) if tested is None else tested[self._outside(np.take(new, tested, axis=0))]
        if len(out) == 0:
            self.n_left_outside = 0
            return 0.0
        old = np.asarray(old_pc(out), dtype=float) if callable(old_pc) else np.asarray(old_pc, dtype=float)[out]
        step = new[out] - old
        inside_before = self._phi(old) < 0.0
        if inside_before.any():  # bisection on t in [0, 1]: old + t step stays inside up to t_in
            k = np.nonzero(inside_before)[0]
            lo, hi = np.zeros(len(k)), np.ones(len(k))
            for _ in range(_BISECTIONS):
                mid = 0.5 * (lo + hi)
                ok = self._phi(old[k] + mid[:, None] * step[k]) < 0.0
                lo = np.where(ok, mid, lo)
                hi = np.where(ok, hi, mid)
            new[out[k]] = old[k] + (0.5 * lo)[:, None] * step[k]  # half-way to the boundary
        stuck = out[~inside_before]
        for _ in range(_PROJECTIONS):
            if len(stuck) == 0:
                break
            phi, n_pc = self.domain.phi_and_normal(np.ascontiguousarray(new[stuck][:, : self.domain.dim]))
            phi = np.asarray(phi, dtype=float).reshape(-1)
            n_pc = np.asarray(n_pc, dtype=float)
            push = phi + 1e-9 * max(1.0, float(np.abs(new[stuck]).max()))
            new[stuck, : self.domain.dim] -= push[:, None] * n_pc[:, : self.domain.dim]
            stuck = stuck[~(self._phi(new[stuck]) < 0.0)]
        self.n_returned += len(out) - len(stuck)
        self.n_left_outside = len(stuck)
        return float(np.sqrt(((new[out] - old) ** 2).sum(axis=1).max()))

    def may_leave(self, longest, candidates=None, margin=None, candidates_phi=None):
        """The indices of the only particles that moves of at most ``longest`` can take out of the domain, by
        :meth:`adjust_moved`'s rule (``candidates``, ``margin``, ``candidates_phi`` as there), or None: any."""
        if candidates is None or margin is None or longest is None or not self._takes_positions \
                or not longest < 0.5 * margin:
            return None
        candidates = np.asarray(candidates)
        if candidates_phi is not None:
            candidates = candidates[~(np.asarray(candidates_phi) <= -2.0 * longest)]
        return candidates

    def _outside(self, r_pc):
        """Indices of the points of ``r_pc`` not inside (``phi >= 0`` or NaN), :data:`_CHUNK` at a time
        (at 1e6 particles in 3D the level set of all of them and its masks held 10 bytes per particle)."""
        from ..parallel import thread_count, thread_pool  # numba: loaded at the first step, not on import

        def part(first):
            return first + np.nonzero(~(self._phi(r_pc[first:first + _CHUNK]) < 0.0))[0]

        firsts = range(0, len(r_pc), _CHUNK)
        # the chunks on the threads for the package's domains (numba level sets; Ball's without the GIL), a user's
        # level set on the calling thread alone
        nthreads = thread_count(len(r_pc)) if self._takes_positions else 1
        parts = list(thread_pool(nthreads).map(part, firsts)) if nthreads > 1 else [part(f) for f in firsts]
        return np.concatenate(parts) if parts else np.zeros(0, dtype=np.intp)

    def adjust_forces(self, atoms, forces):
        pass

    def __deepcopy__(self, memo):
        # Atoms.copy() deep-copies constraints, and ASE's calculators copy the atoms at every
        # evaluation: share the (immutable) domain, a mesh or table of any size, copy the counters
        twin = type(self)(self.domain)
        twin.n_returned, twin.n_left_outside = self.n_returned, self.n_left_outside
        return twin

    def get_removed_dof(self, atoms):
        return 0

    def index_shuffle(self, atoms, ind):
        pass

    def todict(self):
        return {"name": type(self).__name__, "kwargs": {"domain": repr(self.domain)}}

    def __repr__(self):
        return f"KeepInDomain({self.domain!r})"


def attach_keep_inside(atoms):
    """Attach a :class:`KeepInDomain` for the calculator's domain to ``atoms`` (or a Filter's atoms).

    Returns the constraint (an existing one is reused), or None when the calculator has no domain.
    """
    domain = calculator_domain(atoms)
    if domain is None:
        return None
    target = atoms.atoms if not hasattr(atoms, "constraints") and hasattr(atoms, "atoms") else atoms
    for constraint in target.constraints:
        if isinstance(constraint, KeepInDomain) and constraint.domain is domain:
            return constraint
    constraint = KeepInDomain(domain)
    target.set_constraint(list(target.constraints) + [constraint])
    return constraint
