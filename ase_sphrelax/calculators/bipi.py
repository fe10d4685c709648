"""BIPI's objective as an ASE calculator (Boregowda & Liu 2025, Eq. 2-5).

Energy ``E_BI = (V/2) sum_{a != b} W_ab - sum_a gamma(x_a)`` with forces ``-dE_BI/dx_a =
-(V sum_b grad_a W_ab - grad gamma_a) = -gamma_a grad C_a`` (:mod:`ase_sphrelax.models.bipi`),
exact, so ASE's FIRE and LBFGS minimise BIPI's concentration objective. The per-particle
results of the paper are exposed too: ``gamma`` (Eq. 2), ``grad_gamma`` (Eq. 3),
``concentration`` ``C_a`` (Eq. 4), ``concentration_gradient`` ``grad C_a`` (Eq. 5) and
``wall_gradient``, the sum of ``grad gamma_as`` over the elements closer than ``0.5 dx`` (the
step boundary pressure of Eq. 13-14, used by :class:`~ase_sphrelax.drivers.BIPIPacker`; that
rule is not a gradient and is not part of the forces).

The pair sums ``sum_b W_ab`` and ``sum_b grad_a W_ab`` run through
:func:`ase_sphrelax.kernel_sums.kernel_sums`; the boundary terms through
:class:`ase_sphrelax.boundary.BoundaryIntegrals` on the same neighbour bins.
"""
from __future__ import annotations

import warnings

import numpy as np

from .. import sph
from ..boundary import BoundaryIntegrals, as_boundary
from ..boundary.gamma import BAND_RULES
from ..checks import SpacingWarning, spacing_mismatch
from ..kernel_sums import kernel_sums
from ..models.bipi import J_DEFAULT, BIPIModel, support_from_paper
from ..models.fan import verlet_skin
from .base import SPHCalculator, check_store_list, resolve_store_list

__all__ = ["BIPICalculator", "check_periodic_atoms"]


def check_periodic_atoms(atoms, boundary, dim):
    """One-line error unless ``atoms.pbc`` (and the periodic cell vectors) match the boundary's.

    A bounded boundary needs ``pbc`` False along the ``dim`` axes; a periodic one
    (``boundary.with_cell``) the same ``pbc`` and, along each periodic axis, the cell vector of
    the boundary's period.
    """
    want = boundary.pbc[:dim]
    if not np.array_equal(np.asarray(atoms.pbc[:dim], dtype=bool), want):
        if not want.any():
            raise ValueError(f"atoms.pbc must be False along the {dim} axes of a bounded BIPI domain, got "
                             f"{atoms.pbc}; for periodic directions make the boundary periodic "
                             "(boundary.with_cell(pbc, cell))")
        raise ValueError(f"atoms.pbc must be {want.tolist()} along the {dim} axes (the boundary is periodic in "
                         f"{boundary.periodic.label}), got {atoms.pbc.tolist()}")
    cell = atoms.cell.array
    for i in np.nonzero(want)[0]:
        if not np.allclose(cell[i], boundary.cell[i], rtol=1e-12, atol=0.0):
            raise ValueError(f"atoms.cell[{i}] must be the boundary's period {boundary.cell[i].tolist()}, got "
                             f"{cell[i].tolist()}")


class BIPICalculator(SPHCalculator):
    """BIPI's ``E_BI`` with exact forces, and the paper's per-particle ``gamma``, ``C``, ``grad C``.

    Parameters
    ----------
    h : float
        Kernel **support** radius (``h = 2 h_B``: BIPI2D's ``hsml = 2 dx_r`` is ``h = 4 dx``);
        see :meth:`from_paper` for the paper's ratio ``h_B / dx_r``.
    dx : float
        Particle spacing ``dx_r``; particle volume ``V = dx^d``.
    boundary : BoundarySegments, BoundaryTriangles, a polygonal domain, a Mesh or a file
        The boundary elements (:func:`ase_sphrelax.boundary.as_boundary`); its dimension is the
        calculator's.
    kernel : str
        ``"wendland_c2"`` (the paper's Wendland "quintic").
    J : float
        ``D = J h_B^2`` of the packer's shift (stored in the model; not used by the forces).
    skin : float or None
        Verlet skin (default ``0.1 h``).
    dim : int or None
        Must match the boundary (default: the boundary's).
    store_list : bool or None
        True: evaluations after the first walk a stored Verlet list (4 B per pair within ``h + skin``: about
        630 B per particle in 3D at ``h = 4 dx``). False: every evaluation scans one-shot bins (no list, and no
        stored particle-element candidates), the same values to rounding for less memory and a bin scan per
        evaluation (1.2x the CPU time of a 3D step at 3e4 particles). None (default): True in 2D, False in 3D
        (:func:`~ase_sphrelax.calculators.base.resolve_store_list`; issue 33 item 4, at most 900 B per particle in
        3D).
    band_rule : {"ball", "normal", "centroid"}
        Which part of the boundary feels the step pressure (``wall_gradient``,
        :meth:`ase_sphrelax.boundary.BoundaryIntegrals.compute`): "ball" (default) the part within
        ``0.5 dx`` of the particle; "normal" whole elements whose line/plane is that close (Eq. 14
        as written); "centroid" whole elements whose centroid is (Eq. 21 as written).

    Notes
    -----
    Periodic directions come with the boundary (``boundary.with_cell(pbc, cell)``,
    :mod:`ase_sphrelax.boundary.periodic`): ``atoms.pbc`` must match the boundary's ``pbc`` along
    the ``dim`` axes and ``atoms.cell`` its periods (a bounded boundary: ``pbc`` False). The
    neighbour list then wraps the particles into the cell, and both the pair sums and
    ``gamma`` see the periodic images. 2D particles must lie at z = 0.
    ``C`` and ``grad C`` are undefined where ``gamma = 0`` (a particle farther than ``h``
    outside the boundary): asking for them then raises, naming the particles.

    In 3D the first evaluation in a process fixes glibc's mmap threshold, as the H solve of ALARIC and SPH-ParVI
    does (:data:`ase_sphrelax.sph.MMAP_THRESHOLD`, :func:`~ase_sphrelax.sph.fix_mmap_threshold_once`; it lasts for
    the process, ``sph.MMAP_THRESHOLD = None`` before it keeps glibc's rule). BIPI 3D at 1e4 particles then peaks at
    about 660 B per particle, against up to 850 under glibc's rule (goal 900), at the same speed. In 2D it is left
    alone. Fixed there, every freed per-particle array of a step is given back and the next one is written to fresh
    pages, which made a Step-2c iteration at 1e5 particles about 1.3x slower. Under glibc's rule BIPI 2D stays within
    600 B per particle (``reproductions/speed-scale-memory-2d``).
    """

    implemented_properties = ["energy", "free_energy", "energies", "forces", "gamma", "grad_gamma", "concentration",
                              "concentration_gradient", "wall_gradient"]
    default_parameters = dict(h=None, dx=None, boundary=None, kernel="wendland_c2", J=J_DEFAULT, skin=None, dim=None,
                              band_rule="ball", store_list=None)

    def __init__(self, h=None, dx=None, boundary=None, kernel="wendland_c2", J=J_DEFAULT, skin=None, dim=None,
                 band_rule="ball", store_list=None, **kwargs):
        super().__init__(h=h, dx=dx, boundary=boundary, kernel=kernel, J=J, skin=skin, dim=dim, band_rule=band_rule,
                         store_list=store_list, **kwargs)

    @classmethod
    def from_paper(cls, h_over_dx_paper, dx, boundary, **kwargs):
        """Calculator for the paper's ratio ``h_B / dx_r`` (BIPI2D default 2): ``h = 2 h_B``."""
        return cls(h=support_from_paper(h_over_dx_paper, dx), dx=dx, boundary=boundary, **kwargs)

    def _validate_parameters(self):
        p = self.parameters
        if p.boundary is None:
            raise ValueError("boundary must be given: BoundarySegments, BoundaryTriangles, a polygonal domain, a Mesh "
                             "or a file")
        boundary = as_boundary(p.boundary)
        if p.dim is None:
            p.dim = boundary.dim
        elif p.dim != boundary.dim:
            raise ValueError(f"dim={p.dim!r} but the boundary is {boundary.dim}D")
        super()._validate_parameters()
        self.model = BIPIModel(p.h, p.dx, boundary.dim, p.kernel, p.J)
        p.h, p.dx = self.model.h, self.model.dx
        self.skin = verlet_skin(p.skin, self.model.h)
        if p.band_rule not in BAND_RULES:
            raise ValueError(f"band_rule must be one of {BAND_RULES}, got {p.band_rule!r}")
        check_store_list(p.store_list)
        self.boundary = boundary
        elements = boundary
        if boundary.dim == 2 and p.band_rule != "centroid":
            # runs of collinear segments merged (the polygon's segments): the same integrals over fewer
            # elements (AirFoilFluid: 5224 -> 686); only the "centroid" rule depends on the elements
            elements = boundary.merged()
        self.integrals = BoundaryIntegrals(elements, self.model.h, p.kernel)
        self._nearest_p = None
        self._spacing_checked = None

    def stores_list(self):
        return resolve_store_list(self.parameters.store_list, self.dim)

    def check_atoms(self, atoms, dim, properties):
        check_periodic_atoms(atoms, self.boundary, dim)
        if self._spacing_checked is not True and self._spacing_checked != len(atoms):  # once per particle count
            self.check_spacing(len(atoms))

    def skip_spacing_check(self):
        """No spacing check on later evaluations (a driver evaluating subsets of a set it checked)."""
        self._spacing_checked = True

    def check_spacing(self, n, final=False):
        """Warn (:class:`~ase_sphrelax.checks.SpacingWarning`) when ``n`` particles at spacing ``dx`` cannot
        fill the boundary's region: ``|N dx^d - V|`` beyond the cells the boundary cuts
        (:func:`~ase_sphrelax.checks.spacing_mismatch`, the check of ``sphrelax relax``). BIPI's particle
        volume is ``dx^d``: at another spacing ``C`` and its gradient are off by the ratio.

        ``final=True``: no later check (a driver that checked the whole set and then evaluates subsets
        of it, as :class:`~ase_sphrelax.drivers.BIPIPacker` does in Step 2a)."""
        self._spacing_checked = True if final else n
        boundary = self.boundary
        surface = boundary.surface  # of one period, for periodic boundaries
        message = spacing_mismatch(n, self.model.dx, boundary.dim, float(boundary.domain.volume), surface)
        if message is not None:
            warnings.warn(f"BIPICalculator: {message}", SpacingWarning, stacklevel=4)

    def cutoff(self, atoms, dim):
        return self.model.h, self.skin

    def evaluate(self, state, properties):
        if state.dim == 3:
            sph.fix_mmap_threshold_once()  # the first evaluation of a process (MMAP_THRESHOLD); not in 2D (above)
        model = self.model
        self._nearest_p = None  # the last evaluation's, not kept while this one runs
        # the query fused into the boundary rows: no (particle, element) pair arrays (24 B per pair)
        terms = self.integrals.compute(state.nlist, state.r_pc, band=model.band, band_rule=self.parameters.band_rule,
                                       keep_pairs=False)
        gamma_p, grad_gamma_pc = terms.gamma_p, terms.grad_gamma_pc
        self._nearest_p = terms.nearest_p
        out = dict(gamma=gamma_p, grad_gamma=grad_gamma_pc, wall_gradient=terms.near_pc)
        if set(properties) <= {"gamma", "grad_gamma", "wall_gradient"}:
            return out
        sums = kernel_sums(state.nlist, state.r_pc, model.h, model.kernel, planar=state.dim < 3)
        # the energy and forces only when asked for (BIPIPacker asks for grad C alone: 32 B per particle less)
        energetic = not set(properties) <= {"gamma", "grad_gamma", "wall_gradient", "concentration",
                                            "concentration_gradient"}
        if energetic:
            energies_p = model.energies(sums.w_p, gamma_p)
            out.update(energy=float(energies_p.sum()), energies=energies_p)
        # model.gradient (V sum grad W - grad gamma) in the sums' own new array: no (N, 3) temporaries
        gradient_pc = np.subtract(np.multiply(model.volume, sums.grad_pc, out=sums.grad_pc), grad_gamma_pc,
                                  out=sums.grad_pc)
        empty = np.nonzero(gamma_p <= 0.0)[0]
        if len(empty):
            if {"concentration", "concentration_gradient"} & set(properties):
                raise ValueError(f"particles {empty[:10].tolist()} lie more than h outside the boundary (gamma = 0): "
                                 "their concentration C_a is undefined")
            out["forces"] = np.negative(gradient_pc, out=gradient_pc)
            sph.release_pair_buffers(state.nlist)
            return out  # C and grad C are not stored: asking for them later raises
        out["concentration"] = model.concentration(sums.w_p, gamma_p)
        if energetic:
            out["concentration_gradient"] = gradient_pc / gamma_p[:, None]
            out["forces"] = np.negative(gradient_pc, out=gradient_pc)  # in place: one (N, 3) array fewer at once
        else:  # grad C alone (BIPIPacker): in the gradient's own array, no second (N, 3) array
            out["concentration_gradient"] = np.divide(gradient_pc, gamma_p[:, None], out=gradient_pc)
        sums = gradient_pc = None
        sph.release_pair_buffers(state.nlist)
        return out

    def boundary_distances(self, atoms=None):
        """Distance from each particle to its nearest boundary element within the kernel support (inf
        beyond), from the last evaluation (``atoms`` given: evaluated for them first)."""
        if atoms is not None or self._nearest_p is None:
            self.get_property("gamma", atoms)
        return self._nearest_p.copy()

    # -- convenience ------------------------------------------------------------------
    def get_gamma(self, atoms=None):
        return self.get_property("gamma", atoms)

    def get_concentration(self, atoms=None):
        return self.get_property("concentration", atoms)

    def get_concentration_gradient(self, atoms=None):
        return self.get_property("concentration_gradient", atoms)
