"""Fan et al.'s total error as an ASE calculator.

Energy (Fan Eq. 3.8), with ``v0 = vt`` (Appendix A)::

    E = sum_{i,j} W(|x_i - x_j|, h) v0 vt  -  V  +  sum_i 2 vt I(-phi(x_i)),
    I(s) = int_s^h W1(max(r, 0), h) dr,

where the double sum includes ``i = j``, ``V`` is the domain volume and
``W1`` is the kernel profile normalised on ``[-h, h]`` (Eq. 3.5). Its negative
gradient is exactly Eq. 3.17 inside and Eq. 4.4 with the boundary term:

    F_i = 2 v0 vt sum_{j != i} W'(r_ij) e_ij  -  2 W1(max(-phi_i, 0), h) vt n_i,

with ``e_ij = (x_j - x_i) / r_ij``. That is the ``boundary_term="level_set"`` form; the
default for domains with boundary elements (Polygon, Box, polygonal CSG, Mesh) replaces
``I(-phi_i)`` by the exact missing kernel mass ``1 - gamma_i`` of the boundary and the
boundary force by ``2 vt grad gamma_i`` (:class:`~ase_sphrelax.models.fan.FanModel`), which
stays exact at corners, tips, edges and vertices (issue 33 item 3). Stress (periodic cells, no domain) is the
exact strain derivative of ``E`` divided by the cell volume, including the
``-V`` term and, when ``dx`` is None, the dependence of ``v0 = V / N`` on the cell.
"""
from __future__ import annotations

import numpy as np

from ..domains import Domain
from ..kernel_sums import pair_potential_sums
from ..models.fan import FanModel, verlet_skin
from .base import SPHCalculator, periodic_measure

__all__ = ["FanCalculator", "MAX_SKIN_FACTOR"]

MAX_SKIN_FACTOR = {1: 1.0, 2: 3.0, 3: 1.0}
"""The adaptive skin's limit over the default 0.1 h, by dimension (1: fixed). On Fan's circle at 1e5 particles (FIRE
to the interior mean 6e-4, one thread, runs interleaved) a fixed 0.3 h took 0.85x the CPU time of 0.1 h and the
adaptive skin 0.91x (17 builds instead of 44). On the sphere a wider list costs more in 3D: at 3e4 a fixed 0.2 h and
0.3 h took 1.07x and 1.08x; an adaptive skin up to 0.15 h took 0.97x the time of 0.1 h at 1e5 on one thread and at
1e6 on two (``reproductions/speed-fan-1e6/skin_scan.py``, ``results/skin_3d_1e5.json``, ``skin_3d_1e6.json``) but
raised the 50-step peaks of SPHFIRE and SPHLBFGS at 1e6 to 561 and 609 B per particle beyond the Atoms (383 and 574
at 0.1 h, two threads; issue 33's goal 600): not kept. 1D: not measured."""


class FanCalculator(SPHCalculator):
    """Total error E of Fan et al. (Eq. 3.8) with forces -dE/dx (Eq. 3.17, 4.4).

    The model (volumes, self and boundary terms, stress correction) is
    :class:`ase_sphrelax.models.fan.FanModel` (``self.model``); this calculator sums
    its pair potential with :func:`ase_sphrelax.kernel_sums.pair_potential_sums`.

    Parameters
    ----------
    h : float
        Kernel cut-off (support) radius, in length units (Fan's ``h``, e.g. ``2.6 * dx``).
    dx : float or None
        Background cell size: ``v0 = vt = dx**dim`` (Appendix A). With None,
        ``v0 = vt = V / N`` (Eq. 3.2), with ``V`` the domain volume or, for a
        periodic cell, its area (2D) or volume (3D).
    domain : Domain or None
        Level set ``phi`` (negative inside) with ``phi_and_normal``; adds the
        boundary term of Eq. 3.8 / 4.4. None is the interior case (periodic or free).
    dim : {1, 2, 3} or None
        None (default): the domain's dimension, else inferred from the atoms at each
        evaluation by :func:`ase_sphrelax.checks.resolve_dim` (2D: every z = 0 and the cell
        not periodic in z). Atoms that do not match ``dim`` (3D atoms with ``dim=2``, 2D atoms
        with ``dim=3``, 2D atoms off z = 0) raise a ValueError naming the remedy.
    kernel : str
        Kernel name (:data:`ase_sphrelax.kernels.KERNEL_NAMES`); Fan uses ``"wendland_c2"``.
    skin : float or None
        Verlet skin of the neighbour list; None (default): ``0.1 * h``, growing up to
        :data:`MAX_SKIN_FACTOR` times that while the list is rebuilt every few evaluations (:meth:`max_skin`).
    boundary_term : {"auto", "gamma", "level_set"}
        The boundary part of Eq. 3.8 (:class:`~ase_sphrelax.models.fan.FanModel`): ``"gamma"``
        the exact missing kernel mass ``2 vt (1 - gamma_i)`` of the boundary's segments or
        triangles, ``"level_set"`` Fan's ``2 vt I(-phi_i)``; ``"auto"`` (default): ``"gamma"``
        when the domain has boundary elements, else ``"level_set"``.

    Notes
    -----
    ``free_energy`` equals ``energy``; ``energies`` splits ``E`` per particle:
    ``v0 vt sum_j W_ij - V/N + 2 vt I(-phi_i)``. Two coincident particles give
    zero mutual force (the kernel is flat at r = 0), never NaN.
    """

    implemented_properties = ["energy", "free_energy", "energies", "forces", "stress"]
    default_parameters = dict(h=None, dx=None, domain=None, dim=None, kernel="wendland_c2", skin=None,
                              boundary_term="auto")

    def __init__(self, h=None, dx=None, domain=None, dim=None, kernel="wendland_c2", skin=None, boundary_term="auto",
                 **kwargs):
        super().__init__(h=h, dx=dx, domain=domain, dim=dim, kernel=kernel, skin=skin, boundary_term=boundary_term,
                         **kwargs)

    def _validate_parameters(self):
        super()._validate_parameters()
        self.model = FanModel.from_parameters(self.parameters)
        self.skin = verlet_skin(self.parameters.skin, self.model.h)  # None: 0.1 h of the current h
        self.kernel = self.model.kernel

    def configure(self, dim):
        self.model = self.model.with_dim(dim)
        self.kernel = self.model.kernel

    def model_for(self, atoms):
        """The :class:`~ase_sphrelax.models.fan.FanModel` in the dimension of ``atoms`` (:meth:`resolve_dim`)."""
        self.use_dim(atoms)
        return self.model

    def volumes(self, atoms):
        """:class:`~ase_sphrelax.models.fan.FanVolumes` (V, v0, measure) of ``atoms``."""
        model = self.model_for(atoms)
        return model.volumes(len(atoms), periodic_measure(atoms.cell.array, atoms.pbc, model.dim))

    def check_atoms(self, atoms, dim, properties):
        if "stress" in properties:
            self.model.check_stress(self.volumes(atoms), atoms.cell.volume)

    def cutoff(self, atoms, dim):
        return self.model.h, self.skin

    def max_skin(self, skin, dim):
        """With the default skin (``skin=None``) the list's skin adapts up to :data:`MAX_SKIN_FACTOR` ``[dim]``
        times it (:class:`~ase_sphrelax.neighbors.NeighborList`'s ``max_skin``): an optimiser's large early
        moves rebuild a 0.1 h list every 3-4 steps; a given ``skin`` stays fixed."""
        return None if self.parameters.skin is not None else MAX_SKIN_FACTOR[dim] * skin

    def _near_wall(self, state):
        """The particles that can be within h of the wall: those within h + skin at the list's build (they have
        moved less than skin / 2 since), found again at each build; None (all) without a stored list."""
        nlist = state.nlist
        if nlist is None or not nlist.stored or self.model.boundary_term != "level_set" \
                or not isinstance(self.model.domain, Domain):  # a Domain's phi is a signed distance (1-Lipschitz)
            return None
        key = self._near_key_of(nlist)
        if getattr(self, "_near_key", None) != key:
            self._near = None  # the old set goes first
            self._near = self.model.near_wall(nlist.positions_at_build, self.model.h + nlist.skin)
            self._near_phi = np.empty(len(self._near))  # their level set at each evaluation (wall_candidates)
            self._near_phi_at = None
            self._near_key = key
        return self._near

    def _near_key_of(self, nlist):
        """What the particles near the wall (:meth:`_near_wall`) were found for: the list, its build, the model."""
        return id(nlist), nlist.builds, id(self.model)

    def wall_candidates(self, domain):
        """``(indices, margin, phi_k)``: at the positions of this calculator's last evaluation every particle not in
        ``indices`` lies at least ``margin`` inside ``domain`` (``phi <= -margin``), and candidate k has the level set
        ``phi_k[k]`` (computed there by the wall term); or None when not known.

        Known for the level-set term on a :class:`~ase_sphrelax.domains.base.Domain` (a signed distance) that is this
        calculator's domain, with a stored Verlet list: the particles within ``h + skin`` of the wall at the list's
        build (:meth:`_near_wall`), and ``margin = h + skin / 2``, since the list was valid at that evaluation (no
        particle had moved ``skin / 2`` since the build). For
        :meth:`~ase_sphrelax.drivers.keep_inside.KeepInDomain.adjust_moved`: a step whose moves are all shorter than
        the margin can take only these particles out of the domain."""
        nlist = self.nlist
        if domain is None or domain is not getattr(self.model, "domain", None) or nlist is None or not nlist.stored \
                or nlist.build_pending or getattr(self, "_near_key", None) != self._near_key_of(nlist) \
                or self._near_phi_at != self._evaluations:
            return None
        return self._near, self.model.h + 0.5 * nlist.skin, self._near_phi

    def evaluate(self, state, properties):
        model, r_pc = self.model, state.r_pc
        vols = model.volumes(len(r_pc), periodic_measure(state.cell, state.atoms.pbc, state.dim))
        want_stress = "stress" in properties
        # forces alone (an optimiser's step): no energy terms computed; E is computed when asked for
        want_energy = want_stress or not set(properties) <= {"forces"}
        n = len(r_pc)
        # the previous forces array, written again (not through a rebuild: its peak does not hold it)
        forces_out = self.spare_forces(n)
        if state.nlist is None or state.nlist.build_pending:
            forces_out = None
        # interior: sum_{i != j} = 2 sum_pairs, plus N self terms
        pair_e_p, f_pc, virial = pair_potential_sums(state.nlist, r_pc, model.h, model.pair_prefactor(vols.v0),
                                                     model.kernel, want_virial=want_stress,
                                                     planar=state.dim < 3, want_energy=want_energy,
                                                     keep_scratch=state.dim < 3, forces_out=forces_out)
        forces_out = None
        # the accumulators' pages kept between sums in 2D only: there the peak lies inside the pair sum (SPHFIRE 292
        # B per particle at 1e6 either way, 0.97x the CPU time); in 3D they added 42 and 34 B to the 50-step peaks of
        # SPHFIRE and SPHLBFGS at 1e6 (425 and 607 against 383 and 573, two threads; the 600 B goal)
        energies_p = pair_e_p  # a fresh array of the pair sums: completed in place
        if want_energy:
            energies_p += model.self_energy(n, vols.v0, vols.volume) / n
        if model.domain is not None:
            # the boundary elements are found on the bins of the neighbour list (not periodic images)
            nlist = None if any(state.atoms.pbc) else state.nlist
            near = self._near_wall(state)
            model.boundary(r_pc, vols.v0, nlist=nlist, out=(energies_p, f_pc),  # added in place
                           candidates=near, phi_out=None if near is None else self._near_phi)
            if near is not None:
                self._near_phi_at = self._evaluations  # the candidates' level set at these positions
            if state.first:  # the first evaluation of these atoms: say so if some are far outside
                model.warn_far_outside(r_pc, type(self).__name__)
        if not want_energy:
            return dict(forces=f_pc)
        energy = float(energies_p.sum())
        out = dict(energy=energy, energies=energies_p, forces=f_pc)
        if want_stress:
            out["stress"] = model.stress(virial, energy, vols, state.atoms.cell.volume)
        return out
