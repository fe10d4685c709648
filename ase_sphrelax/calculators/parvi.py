"""ParVICalculator: the SPH-ParVI forces (Huang 2024, Algorithms 1 and 2) as an ASE Calculator (d <= 3).

The physics is :class:`~ase_sphrelax.models.parvi.ParVIModel` (any dimension); this wraps it
for ASE Atoms: d-dimensional particles live in the first ``dim`` coordinates (the others must
be zero: a mismatch is an error), the space is open (``pbc`` false on those axes), and every
particle has the mass ``m = 1/N`` of the model (or ``mass``), so ``forces = m dv/dt``.

Energy. With the score force, a barotropic EOS (isothermal or Tait) and summation densities
(fixed or adaptive support) the forces are exactly minus the gradient of

    ``E = sum_a m u(rho_a) - alpha sum_a m log p(x_a)``,  ``u'(rho) = P/rho^2``

(viscosity, which vanishes at rest, aside), and ``energy`` = ``free_energy`` = E (it needs
``log_density``). The pressure formulations, Eq. 8's regularisation and continuity densities
are not gradient systems: ``conservative`` is False and asking for the energy raises
``PropertyNotImplementedError``. Viscosity (Eq. 6 or 5b) uses the Atoms' velocities, so the
calculator compares momenta when deciding whether a result is cached.
"""
from __future__ import annotations

import numpy as np
from ase.calculators.calculator import PropertyNotImplementedError

from ..checks import check_positive
from ..models.parvi import CountingTarget, ParVIModel
from .base import SPHCalculator

__all__ = ["ParVICalculator"]


class ParVICalculator(SPHCalculator):
    """SPH-ParVI forces on ASE Atoms.

    Parameters
    ----------
    log_density, score : callable or None
        Vectorised ``(M, d) -> (M,)`` and ``(M, d) -> (M, d)``; a missing score is computed
        by central differences of ``log_density`` (counted in :attr:`evaluations`).
    dim : {1, 2, 3} or None
        None (default): inferred from the Atoms (:func:`ase_sphrelax.checks.resolve_dim`).
    formulation : {"force", "pressure-log", "pressure-inverse"}
    eos : {"isothermal", "tait"}
    alpha, c0, rho0, gamma, kernel, h, n_neighbours, viscosity, viscosity_alpha, nu, regularisation, eps, mass
        As in :class:`~ase_sphrelax.models.parvi.ParVIModel`; ``c0`` defaults to ``sqrt(alpha)``.
    """

    implemented_properties = ["energy", "free_energy", "forces", "densities"]
    velocity_dependent = True
    default_parameters = dict(log_density=None, score=None, dim=None, formulation="force", eos="isothermal", alpha=1.0,
                              c0=None, rho0=None, gamma=7.0, kernel="wendland_c2", h="adaptive", n_neighbours=None,
                              viscosity="linear", viscosity_alpha=0.1, nu=0.05, regularisation=0.0, eps=1e-10,
                              mass=None)

    def _validate_parameters(self):
        super()._validate_parameters()
        self.model = None
        # validates every parameter; with dim=None, 2 until the first Atoms (configure rebuilds it)
        self.model = self._model(self.parameters.dim or 2)
        self.dim = self.parameters.dim

    def _model(self, dim):
        p = self.parameters
        target = CountingTarget(p.log_density, p.score, dim)
        alpha = check_positive("alpha", p.alpha)
        return ParVIModel(target, dim, formulation=p.formulation, eos=p.eos, alpha=alpha,
                          c0=float(np.sqrt(alpha)) if p.c0 is None else p.c0, rho0=p.rho0, gamma=p.gamma,
                          kernel=p.kernel, h=p.h, n_neighbours=p.n_neighbours, viscosity=p.viscosity,
                          viscosity_alpha=p.viscosity_alpha, nu=p.nu, regularisation=p.regularisation, eps=p.eps,
                          mass=p.mass)

    def configure(self, dim):
        if self.model is None or self.model.dim != dim:
            h_tol = self.model.h_tol
            self.model = self._model(dim)
            self.model.h_tol = h_tol

    @property
    def nlist(self):
        """The model's neighbour list (a cell list for d <= 3)."""
        model = self.__dict__.get("model")
        return None if model is None else model.nlist

    @nlist.setter
    def nlist(self, value):  # the base class resets it; the model owns the list
        model = self.__dict__.get("model")
        if model is not None:
            model.nlist = value

    @property
    def conservative(self):
        """True when the forces are minus the gradient of the reported energy."""
        return self.model.conservative

    def non_conservative_reason(self):
        m = self.model
        return f"formulation={m.formulation!r} with density={m.density!r} and regularisation={m.regularisation}"

    @property
    def evaluations(self):
        """(density, score) evaluations so far, per particle."""
        return self.model.target.n_density, self.model.target.n_score

    def check_atoms(self, atoms, dim, properties):
        if len(atoms) < 2:
            raise ValueError(f"atoms: SPH-ParVI needs at least 2 particles, got {len(atoms)}")
        if np.any(np.asarray(atoms.pbc)[:dim]):
            raise ValueError(f"atoms.pbc: ParVICalculator works in open space, got pbc={atoms.pbc.tolist()}")
        if ({"energy", "free_energy"} & set(properties)) and not self.model.target.has_density:
            raise PropertyNotImplementedError("energy: needs log_density (only a score was given)")

    def cutoff(self, atoms, dim):
        return None  # the model keeps its own list (a k-d tree beyond 3D)

    def evaluate(self, state, properties):
        d = state.dim
        v = state.v_pc[:, :d] if state.v_pc is not None and self.model.viscosity != "none" else None
        want_energy = "energy" in properties or "free_energy" in properties
        ev = self.model.evaluate(np.ascontiguousarray(state.r_pc[:, :d]), v, want_energy=want_energy)
        forces = np.zeros((len(state.r_pc), 3))
        forces[:, :d] = ev.forces
        out = dict(forces=forces, densities=ev.rho)
        if ev.energy is not None:
            out["energy"] = ev.energy
        return out
