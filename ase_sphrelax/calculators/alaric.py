"""ALARIC (Vela Vela et al.) as an ASE calculator: energy = the ALARIC potential, forces = its exact negative gradient.

See :mod:`ase_sphrelax.models.alaric` for the potential, its gradient and what happens where the
target vanishes; :mod:`ase_sphrelax.sph` for the adaptive smoothing lengths (Eq. 31-32), Omega
(Eq. 13) and the grad-h pressure force (Eq. 34). Friction, viscosity, velocity stops and
splitting are the dynamics' (:class:`~ase_sphrelax.drivers.ALARICDynamics`).
"""
from __future__ import annotations

import numba
import numpy as np
from ase.calculators.calculator import PropertyNotImplementedError

from .. import sph
from ..checks import check_positive
from ..kernels import get_kernel
from ..models import alaric as model
from ..neighbors import NeighborList, release_free_memory
from ..pairs import RELEASE_MIN_POINTS
from .base import SPHCalculator, check_store_list, resolve_store_list

__all__ = ["ALARICCalculator", "FLOOR", "PAPER_ETA", "PAPER_OMEGA_FLOOR", "QUADRATIC_WALL_FACTOR", "WALL_FORMS",
           "needed_ghosts"]

PAPER_OMEGA_FLOOR = 0.05  # form="paper" only (no energy there): its default floor of Omega in the forces
# form="paper": default eta (n H^d = eta^d, support H) and background pressure; the one-ingredient-at-a-time study
# reproductions/alaric-eq29-stability chose them (README there)
PAPER_ETA = 2.5
BACKGROUND_PRESSURES = ("deficit",)
FLOOR = 1e-4  # default density floor of ln rho*, relative to the largest target value at the particles
# default Verlet skin, relative to the mean H at the first evaluation, as Fan's 0.1 h: 0.2 listed 1.17x (2D) / 1.29x
# (3D) the pairs at 1e5; ALARICDynamics on Fig. 13 rebuilds at nearly every step with either (0.2: 89 %, 0.1: 100 %
# of the steps; benchmarks/results/alaric_skin_rebuilds.json, reproductions/speed-alaric-lammps/README.md)
SKIN_FACTOR = 0.1
# boundary="mirror": the stored ghost set reaches this much deeper than needed (times the mean H at the first
# evaluation), so that it changes only when particles moved that far (_solve_with_ghosts)
GHOST_SKIN = 0.25
WALL_FORMS = ("linear", "quadratic")  # the domain wall's energy per particle outside (wall_form)
# wall_form="quadratic": default L = this times (V_domain / N)^(1/d) (reproductions/alaric-fig8-3d-isolate: 0.5)
QUADRATIC_WALL_FACTOR = 0.5


@numba.njit(cache=True)
def _wrapped_points(r_pc, inverse_cc, cell_cc, periodic_c, origin_c, d):
    """``origin + x`` with x the first ``d`` Cartesian components of ``r_pc`` (N, 3), wrapped into the cell along
    the periodic axes: fractional coordinates ``s = r @ inverse``, ``s mod 1`` where periodic, back by ``s @ cell``
    (the sums in the order of the numpy expressions this replaces, so the results are the same bit for bit)."""
    n = r_pc.shape[0]
    out = np.empty((n, d))
    frac = np.empty(3)
    for p in range(n):
        for c in range(3):
            s = r_pc[p, 0] * inverse_cc[0, c] + r_pc[p, 1] * inverse_cc[1, c] + r_pc[p, 2] * inverse_cc[2, c]
            frac[c] = s % 1.0 if (c < d and periodic_c[c]) else s
        for c in range(d):
            out[p, c] = frac[0] * cell_cc[0, c] + frac[1] * cell_cc[1, c] + frac[2] * cell_cc[2, c] + origin_c[c]
    return out


def needed_ghosts(phi_p, h_p, skin=0.0):
    """Which particles' mirror ghosts can add to a real particle's density, pressure or viscous force (bool (N,)).

    A ghost of a particle at depth ``delta = -phi > 0`` lies at least ``delta`` outside the domain (a ball: exactly;
    a convex polygon: beyond the half-plane of the face its ray leaves by), so it is at least ``delta + delta_b``
    from a real particle ``b`` inside (``delta - phi_b`` from one outside) and within ``max(H_b, H_a)`` of some ``b``
    only if ``delta < max(max_b (H_b + phi_b), H_a + max_b phi_b)``. A particle outside (``phi >= 0``) always
    counts (its ghost is inside). ``skin`` widens the test by that depth (the stored set of ``_solve_with_ghosts``).

    Parameters
    ----------
    phi_p : ndarray (N,), signed distance to the boundary (positive outside)
    h_p : ndarray (N,), support radii
    skin : float
    """
    reach = float(np.max(h_p + phi_p))
    return (phi_p >= 0.0) | (-phi_p < np.maximum(reach, h_p + float(phi_p.max())) + skin)


class ALARICCalculator(SPHCalculator):
    """The ALARIC potential ``U = sum_a m c_s^2 ln(rho_a / rho*(x_a))`` with exact forces.

    Parameters
    ----------
    target_density : callable
        ``rho*``: vectorised ``(N, dim) -> (N,)``, finite and ``>= 0``, not zero everywhere.
    dim : {1, 2, 3} or None
        None (default): the domain's, else inferred from the Atoms (:func:`ase_sphrelax.checks.resolve_dim`;
        1D atoms lie on the x axis, e.g. with ``atoms.info["dim"] = 1``).
    target_gradient : callable or None
        ``grad rho*``: ``(N, dim) -> (N, dim)``; None uses central differences of ``target_density``
        (step ``fd_step``; the forces are then the gradient up to that error).
    mass : float or None
        Equal particle mass ``m``; None: Eq. 44 at the first evaluation, ``m = mean(rho*_a / n_a)``,
        then kept (:meth:`set_mass` changes it without discarding the neighbour list).
    cs2 : float
        Isothermal ``c_s^2 = (gamma - 1) u`` (Eq. 30); scales energy and forces.
    kernel : str
        Default ``"wendland_c4"`` (Eq. 6).
    eta : float or None
        ``n_a H_a^d = eta^d`` (Eq. 31) for support ``H``; default :func:`ase_sphrelax.sph.default_eta`
        (Phantom's 1.5 for support 2h, i.e. 3.0 for C4).
    form : {"log", "squares", "paper"}
        ``"log"``: the conservative potential above. ``"squares"``: the conservative least-squares
        potential ``U = sum_a m c_s^2 (rho_a - rho*(x_a))^2 / (2 rho_ref)`` (``rho_ref`` the mean target at
        the first evaluation), whose minimum is the paper's fixed point ``rho_a = rho*(x_a)``.
        ``"paper"``: Eq. 29, ``P_a = c_s^2 (rho_a - rho*(x_a))`` in the pressure term, no body force;
        non-conservative: forces only (``energy`` raises PropertyNotImplementedError); the log
        potential, a monitor, is ``results["monitor"]`` (:meth:`monitor`). By default it runs with the
        constant background pressure ``background_pressure="deficit"`` and ``eta = PAPER_ETA`` (2.5), the stable
        recipe of the study ``reproductions/alaric-eq29-stability``; ``background_pressure=0`` and
        ``eta=3.0`` give the bare Eq. 29 (which pairs particles for Delta <= 0.1 in Eq. 46).
    background : float
        ``form="squares"`` or ``"paper"``: a background pressure ``beta c_s^2 rho`` (``beta`` = ``background``)
        added to the form's pressure, so that it stays positive near equilibrium (no tensile instability where
        ``|rho - rho*| < beta rho``). In ``"squares"`` it is the energy ``beta sum_a m c_s^2 ln rho_a`` (exact
        gradient: the isothermal pressure force, no body force), which shifts the minimum away from
        ``rho_a = rho*(x_a)`` by an amount that vanishes with ``beta``. Default 0.
    background_pressure : "deficit", float or None
        ``form="paper"`` only: a pressure ``P_B``, the same for every particle, added to Eq. 29's
        ``P_a = c_s^2 (rho_a - rho*_a)``. ``"deficit"`` (the paper form's default, None): at every evaluation
        ``P_B = c_s^2 max_a (rho*_a - rho_a)_+``, the smallest constant that makes every ``P_a + P_B >= 0``, so the
        pressure is never tensile (the pairing instability of Eq. 29 at Eq. 46's low-density well). A number: that
        fixed ``P_B >= 0``; ``0`` switches it off. In the continuum a constant pressure exerts no force; in the
        symmetric SPH force (Eq. 34) it adds ``-m P_B sum_b m [1/(Omega_a rho_a^2) grad_a W_ab(H_a) +
        1/(Omega_b rho_b^2) grad_a W_ab(H_b)]``, which is ``-grad`` of ``-P_B sum_b m / rho_b`` (minus ``P_B`` times
        the SPH volume) for a fixed ``P_B``: a force towards evenly spaced particles that vanishes on a regular
        arrangement (the zeroth-order error of SPH). With ``"deficit"``, ``P_B = 0`` wherever ``rho_a >= rho*_a``
        for every particle, so the paper's fixed point (``rho_a = rho*_a``; ``rho - rho* = const >= 0`` before the
        Eq. 44 mass reset) is still an exact fixed point. ``P_B`` depends on the state through the max: the
        dynamics stay non-conservative, a driver (the form has no energy; ``energy`` raises). The conservative
        forms refuse a non-zero value (their pressure is the gradient of their energy; ``background`` is theirs).
    omega_floor : float or None
        ``form="paper"`` only (it has no energy, so no gradient to keep): Omega (Eq. 13) is replaced by
        ``max(Omega, omega_floor)`` in its forces; default :data:`PAPER_OMEGA_FLOOR` (0.05), ``0`` for the
        exact Omega. The conservative forms always use the exact Omega (a floor there made the force differ
        from -grad U by 35x at a pair 1e-4 H apart), and refuse ``omega_floor``.
    domain : Domain or None
        Particles outside it (``phi > 0``, ``phi`` its signed distance) feel a wall energy (``wall_form``), whose
        exact gradient is in the forces (and, through ``-F (x) x``, in the stress).
    boundary : {"wall", "mirror"}
        What the kernels see at the domain's edge. ``"wall"``: nothing (truncated kernels: an edge particle's
        SPH density is about half the interior's). ``"mirror"``: every particle whose mirror image
        (:func:`ase_sphrelax.models.alaric.mirror_map`) can be within reach of a real particle (:func:`needed_ghosts`)
        has one, of the same mass and the same H, that counts in the densities ``rho_a`` of the real particles
        (ghosts carry no energy of their own); the energy is then a function of the real positions only and the
        forces its exact gradient (the ghosts' share mapped back through the mirror's Jacobian). The ghost set is
        stored with a skin (``GHOST_SKIN``) and kept between neighbour-list rebuilds (ghosts beyond every support
        add exactly nothing). Needs a Ball/Circle/Sphere or a convex 2D Polygon
        domain and no periodic axes. The wall stays (it pulls back a particle that left the domain).
    wall_form : {"linear", "quadratic"}
        ``"linear"`` (default; every stored figure used it): ``U_wall = m c_s^2 phi_+ / L`` per particle, with
        ``phi_+ = max(phi, 0)``: its force jumps from 0 to ``m c_s^2 / L`` as a particle crosses the boundary, and
        a leapfrog step across that jump adds energy (the hot, pairing edge layer of Fig. 8 in 3D at N = 26 411,
        ``reproductions/alaric-fig8-3d-isolate``). ``"quadratic"``: ``U_wall = m c_s^2 phi_+^2 / (2 L^2)``,
        whose force ``m c_s^2 phi_+ / L^2`` goes to 0 as ``phi -> 0+``: no force jump (with it that run converged at
        epsilon 1.8e-4 without pairing, ``fig8_3d_isolate/f_n26411_smooth05``).
    wall_length : float or None
        ``L`` of ``wall_form``. Default for ``"linear"``: a tenth of the mean particle spacing
        ``(V_domain / N)^(1/d)`` at the first evaluation (stiff enough to beat the outward pressure on a particle
        alone outside), then kept. Default for ``"quadratic"``: ``0.5 (V_domain / N)^(1/d)`` with the current N at
        every evaluation (it follows splitting, as the experiment ``reproductions/lib/alaric_fig8_isolate.py`` did).
    density_floor : float or None
        ``ln rho*`` uses ``max(rho*, floor)``; default ``1e-4 max rho*`` over the particles of the first
        evaluation (``grad ln rho*`` diverges like ``2/r`` at a quadratic zero of the target, Eq. 46 with
        Delta = 0: with a floor of 1e-12 the CFL step collapsed near the well, measured).
    h_tol : float
        Relative tolerance of the smoothing-length iteration.
    skin : float or None
        Verlet skin (default ``SKIN_FACTOR = 0.1`` times the mean H at the first evaluation, as Fan's).
    store_list : bool or None
        True: evaluations after the first walk a stored Verlet list (4 B per pair within ``H + skin``, ghosts
        included: about 440 B per particle in 3D with mirror ghosts at 1e5). False: every density pass, pressure
        and viscosity sum scans one-shot bins (no list): the same values to rounding (another order of the sums)
        for less memory and a bin scan per sum (1.24x the CPU time of a 3D step at 1e5). None (default): True in
        1D and 2D, False in 3D (:func:`~ase_sphrelax.calculators.base.resolve_store_list`; issue 33 item 4, at most
        900 B per particle in 3D; ``reproductions/speed-scale-memory-alaric``).
    fd_step : float
        Step of the target's finite-difference gradient.
    origin : sequence of dim floats or None
        The target (and the domain) see ``origin + x``, with ``x`` wrapped into the cell along periodic
        axes (ASE cells start at zero: a periodic interval ``[-1, 1)`` is the cell ``[0, 2)`` with
        origin ``-1``).

    Results
    -------
    ``energy``, ``free_energy`` (= energy), ``energies`` (per particle), ``forces``, and the SPH state
    ``density`` (rho_a), ``number_density`` (n_a), ``smoothing_lengths`` (H_a), ``omega``, ``target``
    (rho*(x_a)) and ``epsilon`` (Eq. 45 with the current mass).
    """

    implemented_properties = ["energy", "free_energy", "energies", "forces", "stress"]
    default_parameters = dict(target_density=None, dim=None, target_gradient=None, mass=None, cs2=1.0,
                              kernel="wendland_c4", eta=None, form="log", omega_floor=None, domain=None,
                              background_pressure=None,
                              boundary="wall", background=0.0, wall_form="linear",
                              wall_length=None, density_floor=None, h_tol=1e-8, skin=None, fd_step=1e-6, origin=None,
                              store_list=None)

    def __init__(self, target_density=None, dim=None, **kwargs):
        self.mass = None
        self.h_p = None
        self._skin = None
        self.state = None
        self._floor = None
        self._wall = None
        self._rho_ref = None
        self._ghosts = None
        self._ghost_set = None
        self._band = None
        super().__init__(target_density=target_density, dim=dim, **kwargs)

    @property
    def conservative(self):
        """True when the forces are the exact negative gradient of ``energy`` (forms "log" and "squares")."""
        return self.parameters.form in ("log", "squares")

    def non_conservative_reason(self):
        return f"form={self.parameters.form!r} (Eq. 29; its monitor, the log potential, is results['monitor'])"

    def _validate_parameters(self):
        super()._validate_parameters()
        p = self.parameters
        model.Target(p.target_density, p.dim or "d", p.target_gradient)  # callables, before any evaluation
        check_positive("fd_step", p.fd_step)
        p.mass = check_positive("mass", p.mass, allow_none=True)
        p.cs2 = check_positive("cs2", p.cs2)
        p.h_tol = check_positive("h_tol", p.h_tol)
        p.eta = check_positive("eta", p.eta, allow_none=True)
        p.wall_length = check_positive("wall_length", p.wall_length, allow_none=True)
        if p.wall_form not in WALL_FORMS:
            raise ValueError(f"wall_form must be one of {WALL_FORMS}, got {p.wall_form!r}")
        p.density_floor = check_positive("density_floor", p.density_floor, allow_none=True)
        if p.form not in model.FORMS:
            raise ValueError(f"form must be one of {model.FORMS}, got {p.form!r}")
        if not (np.isfinite(p.background) and p.background >= 0.0):
            raise ValueError(f"background must be a finite number >= 0, got {p.background!r}")
        if p.background > 0.0 and p.form == "log":
            raise ValueError("background is for form='squares' or 'paper' (the log form's pressure c_s^2 rho is "
                             "positive already), got form='log'")
        if p.background_pressure is not None and p.background_pressure not in BACKGROUND_PRESSURES:
            bp = p.background_pressure
            if isinstance(bp, str) or not (np.isfinite(bp) and bp >= 0.0):
                raise ValueError(f"background_pressure must be 'deficit', a finite number >= 0 or None, got {bp!r}")
        if p.form != "paper" and p.background_pressure not in (None, 0, 0.0):
            raise ValueError(f"background_pressure is for form='paper' only (form={p.form!r} has an energy whose "
                             f"gradient is its pressure; see background), got {p.background_pressure!r}")
        if p.omega_floor is not None:
            if p.form != "paper":
                raise ValueError(f"omega_floor is for form='paper' only (form={p.form!r} has an energy whose exact "
                                 f"gradient needs the exact Omega), got omega_floor={p.omega_floor!r}")
            if not (np.isfinite(p.omega_floor) and 0.0 <= p.omega_floor < 1.0):
                raise ValueError(f"omega_floor must be a number in [0, 1) or None, got {p.omega_floor!r}")
        if p.boundary not in model.BOUNDARIES:
            raise ValueError(f"boundary must be one of {model.BOUNDARIES}, got {p.boundary!r}")
        if p.boundary == "mirror" and (p.domain is None or not model.mirror_supported(p.domain)):
            raise ValueError(f"boundary='mirror' needs a Ball (Circle, Sphere) or a 2D Polygon of one convex loop "
                             f"as domain, got domain={p.domain!r}")
        check_store_list(p.store_list)
        if p.skin is not None and (not np.isfinite(p.skin) or p.skin < 0):
            raise ValueError(f"skin must be a finite number >= 0 or None, got {p.skin!r}")
        if p.domain is not None:
            if not hasattr(p.domain, "phi_and_normal"):
                raise TypeError(f"domain must be a Domain with phi_and_normal() or None, got {type(p.domain).__name__}")
            if p.dim is not None and getattr(p.domain, "dim", p.dim) != p.dim:
                raise ValueError(f"domain is {p.domain.dim}D but dim={p.dim}")
        if p.origin is not None:
            origin = np.asarray(p.origin, dtype=float).reshape(-1)
            if not np.all(np.isfinite(origin)) or (p.dim is not None and origin.shape != (p.dim,)):
                raise ValueError(f"origin must be {p.dim or 'dim'} finite numbers or None, got {p.origin!r}")
        self.mass = p.mass
        self.h_p = None
        self._skin = None
        self._floor = p.density_floor
        self._wall = p.wall_length
        self._rho_ref = None
        self._ghosts = None
        self._ghost_set = None
        self._band = None
        if p.dim is not None:
            self.configure(p.dim)
            self.dim = p.dim

    def configure(self, dim):
        """The target, kernel, eta and origin in ``dim`` dimensions."""
        p = self.parameters
        self.target = model.Target(p.target_density, dim, p.target_gradient, p.fd_step)
        self.kernel = get_kernel(p.kernel, dim)
        if p.eta is not None:
            self.eta = p.eta
        else:
            self.eta = PAPER_ETA if p.form == "paper" else sph.default_eta(self.kernel)
        self.origin = np.zeros(dim) if p.origin is None else np.asarray(p.origin, dtype=float).reshape(-1)
        if self.origin.shape != (dim,):
            raise ValueError(f"origin must be {dim} finite numbers or None (the atoms are {dim}D), got {p.origin!r}")
        self.h_p = None

    def quadratic_wall_length(self, n, d):
        """``L`` of the quadratic wall for ``n`` particles in ``d`` dimensions: ``wall_length`` if given, else
        ``QUADRATIC_WALL_FACTOR (V_domain / n)^(1/d)``."""
        p = self.parameters
        if p.wall_length is not None:
            return p.wall_length
        return QUADRATIC_WALL_FACTOR * (float(p.domain.volume) / n) ** (1.0 / d)

    def background_pressure_value(self, rho_p, target_p):
        """``P_B`` of ``form="paper"`` for densities ``rho_p`` and targets ``target_p``: ``c_s^2 max_a (rho*_a -
        rho_a)_+`` for ``"deficit"`` (the default), else the given number."""
        p = self.parameters
        bp = "deficit" if p.background_pressure is None else p.background_pressure
        if bp == "deficit":
            return p.cs2 * max(float(np.max(target_p - rho_p)), 0.0)
        return float(bp)

    # -- public controls for the dynamics (ALARICDynamics) ----------------------------------------------
    def set_mass(self, mass):
        """Change the equal particle mass (Eq. 44 reset) keeping H and the neighbour list."""
        self.mass = check_positive("mass", mass)
        self.reset()

    def reset_smoothing_lengths(self, h_p):
        """Start afresh on new particles (e.g. after splitting, Fig. 2): initial smoothing lengths ``h_p``
        (one per particle), a new neighbour list and the mass by Eq. 44 at the next evaluation."""
        h_p = np.asarray(h_p, dtype=float)
        if h_p.ndim != 1 or not np.all(np.isfinite(h_p)) or np.any(h_p <= 0):
            raise ValueError("h_p must be finite smoothing lengths > 0, one per particle")
        self.h_p = h_p
        self.mass = self.parameters.mass
        self._skin = None
        self._band = None
        self._ghost_set = None
        self.forget_neighbours()

    def viscous_forces(self, v_pc, alpha_p, v_sig):
        """Artificial viscosity (Eq. 35) at the last evaluated positions: ``(forces (N, 3), div v (N,))``.

        ``v_pc`` velocities (N, 3), ``alpha_p`` the switches (Eq. 19-20), ``v_sig`` the signal speed.
        """
        res = self.results
        if "smoothing_lengths" not in res:
            raise RuntimeError("viscous_forces: evaluate the forces first (atoms.get_forces())")
        if self._ghosts is None:
            out = sph.viscosity_forces(self.nlist, self.atoms.positions, v_pc, self.mass, res["smoothing_lengths"],
                                       res["density"], alpha_p, v_sig, self.kernel)
            sph.release_pair_buffers(self.nlist)
            return out
        # with mirror ghosts: a ghost moves as J v of its owner; its share goes back through J^T
        # the pairs see the first d components (the rest are zeros): d velocity and force columns per point, not 3
        owner_g, y_pc, h_q = self._ghosts
        d, n = self.dim, len(v_pc)
        alpha_p = np.asarray(alpha_p, dtype=float)
        # the points' velocities, densities and switches made in the call's arguments: held by the call only, which
        # drops them once gathered (not through the pair loop: 32 B per point in 2D)
        f_qd, div_q = sph.viscosity_forces(self.nlist, y_pc, self._ghost_velocities(v_pc, owner_g, d), self.mass, h_q,
                                           np.concatenate([res["density"], res["density"][owner_g]]),
                                           np.concatenate([alpha_p, alpha_p[owner_g]]), v_sig, self.kernel, dims=d)
        out = self._fold_ghosts(f_qd, n, columns=3), div_q[:n]
        f_qd = div_q = None
        sph.release_pair_buffers(self.nlist)
        return out

    def _ghost_velocities(self, v_pc, owner_g, d):
        """(Q, d) velocities of the particles and their mirror ghosts (a ghost moves as ``J v`` of its owner)."""
        n = len(v_pc)
        v_qd = np.empty((n + len(owner_g), d))
        v_qd[:n] = np.asarray(v_pc)[:, :d]
        v_qd[n:] = np.einsum("gij,gj->gi", self._ghost_jacobians(), v_qd[owner_g])
        return v_qd

    def _fold_ghosts(self, f_qd, n, columns=None):
        """Real particles' forces from those on the real and ghost points: ``F_a + sum_g J_g^T F_g``, with
        ``columns`` columns (default those of ``f_qd``; the first ``dim`` are summed, the rest zeros)."""
        owner_g = self._ghosts[0]
        d = self.dim
        out = np.zeros((n, f_qd.shape[1] if columns is None else columns))
        out[:, :f_qd.shape[1]] = f_qd[:n]
        np.add.at(out[:, :d], owner_g, np.einsum("gji,gj->gi", self._ghost_jacobians(), f_qd[n:, :d]))
        return out

    def _ghost_jacobians(self):
        """The mirror's Jacobians ``J = dg/dx`` (G, d, d) of the ghosts of the last evaluation, computed again from
        their owners' positions (the same values as in :meth:`_solve_with_ghosts`; not stored: 72 bytes per ghost in
        3D)."""
        x_gd = self.points(self.atoms.positions[self._ghosts[0]], self.atoms)
        return model.mirror_images(self.parameters.domain, x_gd)[1]

    # -- the contract's hooks ---------------------------------------------------------------------------
    def check_atoms(self, atoms, dim, properties):
        if "stress" in properties and not (np.all(atoms.pbc[:dim]) and atoms.cell.rank == 3):
            raise PropertyNotImplementedError("stress needs a cell periodic along all dim axes (rank 3: give a 2D cell "
                                              "a c vector) and a conservative form (log or squares)")
        n_min = self.eta**dim / (self.kernel.sigma * self.kernel.f0)
        if len(atoms) < n_min and not np.all(atoms.pbc[:dim]):
            raise ValueError(f"ALARIC needs more than {n_min:.3g} particles (eta^d / (sigma f(0)) kernel neighbours "
                             f"with eta={self.eta}) in an open system, got {len(atoms)}")
        if self.h_p is None or len(self.h_p) != len(atoms):
            h0 = sph.initial_smoothing_length(atoms.positions, atoms.cell.array, atoms.pbc, dim, self.eta)
            self.h_p = np.full(len(atoms), h0)
            self._skin = None
        if self._skin is None:  # fixed from the first evaluation: a skin that follows H would rebuild every step
            p = self.parameters
            self._skin = p.skin if p.skin is not None else SKIN_FACTOR * float(np.mean(self.h_p))

    def stores_list(self):
        """``store_list`` (:func:`~ase_sphrelax.calculators.base.resolve_store_list`): True walks a stored Verlet
        list after the first evaluation, False scans one-shot bins at every sum."""
        return resolve_store_list(self.parameters.store_list, self.dim)

    def cutoff(self, atoms, dim):
        if self.parameters.boundary == "mirror":
            return None  # its own list over the particles and their mirror ghosts (_solve_with_ghosts)
        return self.h_p, self._skin

    def _solve_with_ghosts(self, st):
        """The smoothing lengths with mirror ghosts.

        The energy sees every ghost within reach of a real particle (:func:`needed_ghosts`: its owner is outside the
        domain, or deep by less than the reach of the particles at the edge); the stored ghost set adds those
        within ``self._band`` (the ghost skin) of that, and is kept while it holds every needed ghost, so the
        neighbour list over particles and ghosts is rebuilt only when the Verlet skin is used up. Ghosts farther
        than every support add exactly nothing to the densities and forces. A ghost's H is its owner's (not solved):
        the returned state's H holds the ghosts' rows as well (their owners' new H).
        """
        p = self.parameters
        n, d = len(st.r_pc), st.dim
        if np.any(st.pbc[:d]):
            raise ValueError("boundary='mirror' is for open systems (no periodic axis), got pbc="
                             f"{st.atoms.pbc.tolist()}")
        if self._band is None:
            self._band = GHOST_SKIN * float(np.mean(self.h_p))
        h_p = self.h_p
        while True:
            # x and phi (N, d + 1 numbers) are not held through the solve; the same values again after it
            x_pd = self.points(st.atoms.positions, st.atoms)
            phi_p = np.asarray(p.domain.phi(x_pd), dtype=float)
            cache = self._ghost_set
            need_p = needed_ghosts(phi_p, h_p)
            if cache is None or cache[1] != self._band or len(cache[0]) != n or np.any(need_p & ~cache[0]):
                self._ghost_set = cache = (self._ghost_owners(x_pd, phi_p, h_p, need_p), self._band)
            need_p = None
            owner_g = np.nonzero(cache[0])[0]
            g_gd = model.mirror_images(p.domain, x_pd[owner_g])[0]  # the Jacobians when needed (_ghost_jacobians)
            x_pd = None
            y_pc = np.zeros((n + len(owner_g), 3))
            y_pc[:n] = st.r_pc
            y_pc[n:, :d] = g_gd - self.origin
            g_gd = phi_p = None
            h0_q = np.concatenate([h_p, h_p[owner_g]])
            self.h_p = h_p = h0_q[:n]  # the same values: the last solve's H (particles and ghosts) is not held
            if self.nlist is None:
                self.nlist = NeighborList(h0_q, skin=self._skin)
            state = sph.solve_smoothing_lengths(self.nlist, y_pc, st.cell, st.pbc, 1.0, self.kernel, eta=self.eta,
                                                h0=h0_q, tol=p.h_tol, solve=n, dims=d,
                                                store=self._evaluations > 1 and self.stores_list())
            h0_q = None
            h_p = state.h_p[:n]
            phi_p = np.asarray(p.domain.phi(self.points(st.atoms.positions, st.atoms)), dtype=float)
            if not np.any(needed_ghosts(phi_p, h_p) & ~cache[0]):  # H grew beyond the stored set: again
                break
        h_q = state.h_p  # the solve's own copy: its ghosts' rows become their owners' new H
        h_q[n:] = h_q[owner_g]
        self._ghosts = (owner_g, y_pc, h_q)
        return state

    def _ghost_owners(self, x_pd, phi_p, h_p, need_p):
        """The stored ghost set (bool (N,)): the needed ghosts and those within the ghost skin ``self._band`` of
        them, except a particle at the mirror's centre (no ray; an error if it is needed)."""
        centre = model.mirror_centre(self.parameters.domain)
        at_centre_p = np.all(x_pd == centre, axis=1)
        if np.any(at_centre_p & need_p):
            raise ValueError(f"boundary='mirror': a particle at the mirror's centre {centre.tolist()} is within the "
                             f"ghost band {float(np.max(h_p + phi_p)):.3g} of the boundary (the domain is too small "
                             f"for the smoothing lengths: too few particles)")
        return needed_ghosts(phi_p, h_p, self._band) & ~at_centre_p

    def points(self, r_pc, atoms):
        """Positions as the target sees them: the first ``dim`` components, wrapped into the cell along periodic axes."""
        d = self.dim if atoms is self.atoms else self.use_dim(atoms)  # in evaluate: resolved already
        if np.any(atoms.pbc[:d]):
            # one compiled pass, not a BLAS solve or matmul (those cost 30 ms at 1e5 particles on a loaded 2-core
            # machine, BLAS threads) nor numpy temporaries per column (4 ms at 1e5 in 2D)
            cell = np.ascontiguousarray(atoms.cell.complete().array, dtype=float)
            return _wrapped_points(np.ascontiguousarray(r_pc, dtype=float), np.linalg.inv(cell), cell,
                                   np.asarray(atoms.pbc, dtype=np.bool_), np.asarray(self.origin, dtype=float), d)
        return np.ascontiguousarray(r_pc[:, :d] + self.origin)

    def evaluate(self, st, properties):
        p = self.parameters
        atoms, d, n = st.atoms, st.dim, len(st.r_pc)
        want_stress = "stress" in properties
        # the last evaluation's sums and mirror ghosts go before this one makes its own (the H solve is the peak
        # of memory): self.h_p keeps the smoothing lengths, the only thing the solve starts from
        self.state = self._ghosts = None
        if n >= RELEASE_MIN_POINTS:  # and the heap's free pages (the dynamics' freed arrays) before the list and solve
            release_free_memory()
        # the target first: bad targets fail before any SPH work
        x_pd = self.points(atoms.positions, atoms)
        target_p = self.target.values(x_pd)
        if self._floor is None:
            top = float(target_p.max())
            if top <= 0.0:
                raise ValueError("target_density is zero at every particle")
            self._floor = FLOOR * top
        x_pd = None  # not held through the H solve: the same values again after it
        if p.boundary == "mirror":
            full = self._solve_with_ghosts(st)  # the particles' rows, then the ghosts'
        else:
            full = sph.solve_smoothing_lengths(st.nlist, st.r_pc, st.cell, st.pbc, 1.0, self.kernel, eta=self.eta,
                                               h0=self.h_p, tol=p.h_tol, dims=d,
                                               store=self._evaluations > 1 and self.stores_list())
        # the solve's unit-mass densities (the number densities again) are not kept: rho = m n below
        h_p, n_p, omega_p, count_p, iterations = (full.h_p[:n], full.n_p[:n], full.omega_p[:n],
                                                  full.neighbours_p[:n], full.iterations)
        full = None
        x_pd = self.points(atoms.positions, atoms)
        self.h_p = h_p
        if self.mass is None:
            self.mass = model.reset_mass(target_p, n_p)
        m = self.mass
        rho_p = m * n_p
        state = sph.DensitySums(h_p, rho_p, n_p, omega_p, count_p, iterations)
        h_p = omega_p = count_p = None
        cs2 = p.cs2
        if p.form == "squares":
            if self._rho_ref is None:
                self._rho_ref = float(np.mean(target_p))
            energies_p = m * cs2 * (rho_p - target_p) ** 2 / (2.0 * self._rho_ref)
            if p.background > 0.0:
                energies_p += p.background * m * cs2 * np.log(rho_p)
        else:
            energies_p = m * cs2 * (np.log(rho_p) - np.log(np.maximum(target_p, self._floor)))
        wall_p = None
        if p.domain is not None:
            if self._wall is None and p.wall_form == "linear":
                self._wall = 0.1 * (float(p.domain.volume) / n) ** (1.0 / d)
            phi_p, normal_pc = p.domain.phi_and_normal(x_pd)
            phi_p = np.asarray(phi_p, dtype=float)
            outside = phi_p > 0.0
            # the wall's force acts on the particles outside only: their normals, not an (N, d) array
            normal_od = np.asarray(normal_pc, dtype=float)[outside, :d]
            normal_pc = None
            if p.wall_form == "linear":
                energies_p += m * cs2 * np.maximum(phi_p, 0.0) / self._wall
                wall_p = (outside, normal_od, None)
            else:  # quadratic: U = m c_s^2 phi_+^2 / (2 L^2), dU/dphi = m c_s^2 phi_+ / L^2 (0 at phi = 0)
                stiffness = m * cs2 / self.quadratic_wall_length(n, d) ** 2
                depth_p = np.maximum(phi_p, 0.0)
                energies_p += 0.5 * stiffness * depth_p**2
                wall_p = (outside, normal_od, (stiffness * depth_p)[outside])
                depth_p = None
            phi_p = None
        out = dict(density=rho_p, number_density=n_p, smoothing_lengths=state.h_p, omega=state.omega_p,
                   target=target_p, epsilon=model.epsilon(rho_p, target_p, n_p))
        if self.conservative:
            out.update(energies=energies_p, energy=float(energies_p.sum()))
        else:
            out["monitor"] = float(energies_p.sum())  # the log potential, a monitor of the paper's form
        self.state = state
        if "forces" in properties or want_stress:
            f_pc, f_ext_pc, virial = self._forces(st.r_pc, x_pd, state, target_p, wall_p, want_stress)
            out["forces"] = f_pc
            if want_stress:
                # dU/d(strain): the pair virial plus -sum F_ext (x) x for the position-dependent terms, with x
                # the wrapped position that the strain scales (the target sees origin + x)
                x_w = np.zeros((n, 3))
                x_w[:, :d] = x_pd - self.origin
                d_e = virial - f_ext_pc.T @ x_w
                d_e = 0.5 * (d_e + d_e.T)
                stress_cc = d_e / atoms.get_volume()
                out["stress"] = stress_cc.flat[[0, 4, 8, 5, 2, 1]]
        sph.release_pair_buffers(self.nlist)
        return out

    def _forces(self, r_pc, x_pd, state, target_p, wall_p, want_virial=False, full=None):
        """(forces (N, 3), the position-dependent (target and wall) part of them (N, 3; the forces themselves
        unless ``want_virial``), pair virial); ``state.rho_p`` the densities ``m n``; ``wall_p`` None or (which
        particles are outside, their outward normals, None (linear) or their ``dU/dphi`` (quadratic)); ``full``
        unused (kept for subclasses' calls)."""
        p = self.parameters
        m, cs2 = self.mass, p.cs2
        rho_p = state.rho_p
        # the exact Omega, never floored: a floor here made the force differ from -grad U by 35x at a pair
        # 1e-4 H apart (Omega 1e-3); the stiff force is the dynamics' to resolve (its force time step)
        omega_p = state.omega_p
        if p.form == "paper":
            floor = PAPER_OMEGA_FLOOR if p.omega_floor is None else p.omega_floor
            if floor > 0.0:
                omega_p = np.maximum(omega_p, floor)
        if p.form == "log":
            pr_p = cs2 / (omega_p * rho_p)  # P / (Omega rho^2), P = c_s^2 rho
        elif p.form == "squares":  # de/drho / Omega, e = c_s^2 (rho - rho*)^2 / (2 rho_ref)
            pr_p = cs2 * (rho_p - target_p) / (self._rho_ref * omega_p)
        else:  # Eq. 29: P_eff = c_s^2 (rho - rho*), plus the constant background pressure P_B
            p_b = self.background_pressure_value(rho_p, target_p)
            pr_p = (cs2 * (rho_p - target_p) + p_b) / (omega_p * rho_p**2)
        if p.background > 0.0:  # P += beta c_s^2 rho (squares: the gradient of beta sum m c_s^2 ln rho)
            pr_p = pr_p + p.background * cs2 / (omega_p * rho_p)
        d = self.dim
        # the pairs see the first d coordinates (the rest are zeros): forces (N, d), fewer terms per pair
        if p.boundary == "mirror":  # ghosts carry no energy: pr = 0; their share folds back through J^T
            y_pc, h_q = self._ghosts[1], self._ghosts[2]
            pr_q = np.concatenate([pr_p, np.zeros(len(y_pc) - len(r_pc))])
            pr_p = None
            f_qd, virial = sph.pressure_forces(self.nlist, y_pc, m, h_q, pr_q, self.kernel, dims=d)
            pr_q = None
            f_pd = self._fold_ghosts(f_qd, len(r_pc))
        else:
            f_pd, virial = sph.pressure_forces(self.nlist, r_pc, m, state.h_p, pr_p, self.kernel,
                                               want_virial=want_virial, dims=d)
        # the position-dependent part: its own array only for the virial (stress); else added to f_pd in place
        f_ext_pd = np.zeros_like(f_pd) if want_virial else f_pd
        if p.form == "log":
            above = target_p > self._floor
            if np.any(above):
                sel = slice(None) if np.all(above) else above  # the usual case, all above: views, no masked copies
                f_ext_pd[sel] += (m * cs2 / target_p[sel])[:, None] * self.target.gradients(x_pd[sel])
        elif p.form == "squares":
            grad_pd = self.target.gradients(x_pd)
            f_ext_pd += (m * cs2 * (rho_p - target_p) / self._rho_ref)[:, None] * grad_pd
        if wall_p is not None:
            outside, normal_od, slope_o = wall_p
            if slope_o is None:  # linear: dU/dphi = m c_s^2 / L outside
                f_ext_pd[outside] -= (m * cs2 / self._wall) * normal_od
            else:  # quadratic: dU/dphi = m c_s^2 phi_+ / L^2
                f_ext_pd[outside] -= slope_o[:, None] * normal_od
        f_pc = np.zeros((len(r_pc), 3))
        f_pc[:, :d] = f_pd
        if f_ext_pd is not f_pd:
            f_pc[:, :d] += f_ext_pd
            f_ext_pc = np.zeros((len(r_pc), 3))
            f_ext_pc[:, :d] = f_ext_pd
        else:
            f_ext_pc = f_pc
        return f_pc, f_ext_pc, virial
