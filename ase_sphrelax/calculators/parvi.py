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
from ase.calculators.calculator import PropertyNotImplementedError, all_changes

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
    dim : {1, 2, 3}
    formulation : {"force", "pressure-log", "pressure-inverse"}
    eos : {"isothermal", "tait"}
    alpha, c0, rho0, gamma, kernel, h, n_neighbours, viscosity, viscosity_alpha, nu, regularisation, eps, mass
        As in :class:`~ase_sphrelax.models.parvi.ParVIModel`; ``c0`` defaults to ``sqrt(alpha)``.
    """

    implemented_properties = ["energy", "free_energy", "forces", "densities"]
    velocity_dependent = True
    default_parameters = dict(log_density=None, score=None, dim=2, formulation="force", eos="isothermal", alpha=1.0,
                              c0=None, rho0=None, gamma=7.0, kernel="wendland_c2", h="adaptive", n_neighbours=None,
                              viscosity="linear", viscosity_alpha=0.1, nu=0.05, regularisation=0.0, eps=1e-10,
                              mass=None)

    def _validate_parameters(self):
        super()._validate_parameters()
        p = self.parameters
        target = CountingTarget(p.log_density, p.score, p.dim)
        alpha = check_positive("alpha", p.alpha)
        self.model = ParVIModel(target, p.dim, formulation=p.formulation, eos=p.eos, alpha=alpha,
                                c0=float(np.sqrt(alpha)) if p.c0 is None else p.c0, rho0=p.rho0, gamma=p.gamma,
                                kernel=p.kernel, h=p.h,
                                n_neighbours=p.n_neighbours, viscosity=p.viscosity, viscosity_alpha=p.viscosity_alpha,
                                nu=p.nu, regularisation=p.regularisation, eps=p.eps, mass=p.mass)

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

    @property
    def evaluations(self):
        """(density, score) evaluations so far, per particle."""
        return self.model.target.n_density, self.model.target.n_score

    def _positions(self, atoms):
        dim = self.parameters.dim
        if atoms is None or len(atoms) < 2:
            raise ValueError(f"atoms: SPH-ParVI needs at least 2 particles, got {0 if atoms is None else len(atoms)}")
        r = np.asarray(atoms.positions, dtype=float)
        if not np.all(np.isfinite(r)):
            bad = np.nonzero(~np.all(np.isfinite(r), axis=1))[0]
            raise ValueError(f"atoms.positions must be finite; particles {bad[:10].tolist()} are NaN or inf")
        if np.any(r[:, dim:] != 0.0):
            raise ValueError(f"atoms: dim={dim} but some particles have non-zero coordinates beyond axis {dim - 1}")
        if np.any(np.asarray(atoms.pbc)[:dim]):
            raise ValueError(f"atoms.pbc: ParVICalculator works in open space, got pbc={atoms.pbc.tolist()}")
        return r[:, :dim]

    def calculate(self, atoms=None, properties=("energy",), system_changes=all_changes):
        SPHCalculator.calculate(self, atoms, properties, system_changes)
        r = self._positions(self.atoms)
        v = None
        if self.model.viscosity != "none" and self.atoms.has("momenta"):
            masses = self.atoms.get_masses()
            v = self.atoms.get_momenta()[:, : self.parameters.dim] / masses[:, None]
        want_energy = "energy" in properties or "free_energy" in properties
        if want_energy and not self.model.conservative:
            raise PropertyNotImplementedError(
                f"energy: formulation={self.model.formulation!r} with density={self.model.density!r} and "
                f"regularisation={self.model.regularisation} is not a gradient system (non-conservative forces)")
        if want_energy and not self.model.target.has_density:
            raise PropertyNotImplementedError("energy: needs log_density (only a score was given)")
        ev = self.model.evaluate(r, v, want_energy=want_energy)
        forces = np.zeros((len(self.atoms), 3))
        forces[:, : self.parameters.dim] = ev.forces
        self.results["forces"] = forces
        self.results["densities"] = ev.rho
        if ev.energy is not None:
            self.results["energy"] = ev.energy
            self.results["free_energy"] = ev.energy
