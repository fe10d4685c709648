"""BIPI's physics (Boregowda & Liu, Comput. Phys. Commun. 310 (2025) 109531) without the pair loop.

Conventions. ``h`` is the kernel **support** radius, as everywhere in this package; the paper's
smoothing length ``h_B`` has support ``kappa h_B`` with ``kappa = 2``, so ``h = 2 h_B``. The
paper's and BIPI2D's ratio ``h_B / dx_r`` (BIPI2D's defaults ``dx_r = 0.01``, ``hsml = 0.02``: 2)
is ``h / dx = 2 h_B / dx_r`` here (4 for the defaults). Particle volume ``V = dx_r^d``; the kernel
is Wendland C2 ("quintic" Wendland in the paper, our ``wendland_c2``).

Concentration (Eq. 4-5) with the kernel volume fraction ``gamma_a`` and the boundary terms
``grad gamma_as`` (Eq. 2-3, :mod:`ase_sphrelax.boundary`):

    C_a = sum_b V W_ab / gamma_a                       (b = a included)          (4)
    grad C_a = (sum_b V grad_a W_ab - sum_s grad gamma_as) / gamma_a             (5)

Objective (:class:`BIPIModel`, an energy whose exact gradient is ``gamma_a grad C_a``):

    E_BI = (V / 2) sum_{a != b} W_ab - sum_a gamma(x_a),
    dE_BI / dx_a = V sum_b grad_a W_ab - grad gamma_a = gamma_a grad C_a,

because ``grad gamma(x_a) = int_{Omega cap B} grad_a W = sum_s int_s W n_s dS``. So the forces
``-dE_BI/dx`` are the paper's shifting direction times ``gamma_a``, and ASE's optimisers (FIRE,
LBFGS) can minimise BIPI's objective.

Particle shift of the packer (Eq. 13-15; not a gradient: :class:`~ase_sphrelax.drivers.BIPIPacker`)::

    dx_hat_a = -D [grad C_a - (1 / gamma_a) sum_s (1/2) (p_s / p_a - 1) grad gamma_as]     (14)
    p_s = 2 p_a if |(x_a - x_s) . n_s| < 0.5 dx_r else p_a                               (step pressure)
    dx_a = dx_hat_a, capped at |dx_a| = 0.5 dx_r                                          (15)

with ``D = J h_B^2`` (``J = 0.5``; Sec. 3.2 after Eq. 11). With the step pressure the bracket is
``grad C_a - (1 / (2 gamma_a)) sum_{s near} grad gamma_as``.

Step 2b freezes the particles within ``k_b = 0.6 dx_r`` of the boundary, found "through gamma"
as the paper does: ``gamma_a`` below the value at distance ``k_b`` from a straight wall.
"""
from __future__ import annotations

import numpy as np

from ..checks import check_positive
from ..kernels import get_kernel

__all__ = ["BIPIModel", "KAPPA", "support_from_paper"]

KAPPA = 2.0  # the paper's support kappa h_B
J_DEFAULT = 0.5  # PSTCoeff (Sec. 3.2: D = J h_B^2)
CAP_FRACTION = 0.5  # Eq. 15: |dx_a| <= 0.5 dx_r
BAND_FRACTION = 0.5  # step pressure within 0.5 dx_r of a segment's line
KB_FRACTION = 0.6  # Step 2b: k_b = 0.6 dx_r (BIPI2D's pack_step2b)


def support_from_paper(h_over_dx_paper, dx):
    """Our support ``h`` from the paper's ratio ``h_B / dx_r``: ``h = kappa h_B = 2 (h_B/dx_r) dx``."""
    return KAPPA * check_positive("h_over_dx_paper", h_over_dx_paper) * check_positive("dx", dx)


class BIPIModel:
    """Parameters and per-particle terms of BIPI (Eq. 4, 5, 13-15) and of its objective ``E_BI``.

    Parameters
    ----------
    h : float
        Kernel support radius (``2 h_B``). Must be at least ``dx``.
    dx : float
        Particle spacing ``dx_r``; the particle volume is ``V = dx^d``.
    dim : {2, 3}
    kernel : str
    J : float
        ``D = J h_B^2`` (the paper's 𝒥, BIPI2D's ``PSTCoeff``).

    Attributes
    ----------
    h_b : float
        The paper's smoothing length ``h / 2``.
    volume : float
        ``V = dx^d``.
    diffusion : float
        ``D = J h_B^2``.
    cap, band, k_b : float
        ``0.5 dx`` (Eq. 15), ``0.5 dx`` (the step pressure's band), ``0.6 dx`` (Step 2b).
    """

    def __init__(self, h, dx, dim=2, kernel="wendland_c2", J=J_DEFAULT):
        self.h = check_positive("h", h)
        self.dx = check_positive("dx", dx)
        if dim not in (2, 3) or isinstance(dim, bool):
            raise ValueError(f"dim must be 2 or 3 (the boundary's dimension), got {dim!r}")
        self.dim = int(dim)
        if self.h < self.dx:
            raise ValueError(f"h must be at least dx (support h = 2 h_B; BIPI2D uses h = 4 dx), got h={h!r} < dx={dx!r}")
        self.kernel = get_kernel(kernel, self.dim)
        self.J = check_positive("J", J)
        self.h_b = self.h / KAPPA
        self.volume = self.dx**self.dim
        self.diffusion = self.J * self.h_b**2
        self.cap = CAP_FRACTION * self.dx
        self.band = BAND_FRACTION * self.dx
        self.k_b = KB_FRACTION * self.dx

    def __repr__(self):
        return (f"BIPIModel(h={self.h!r} (h_B={self.h_b!r}, h_B/dx={self.h_b / self.dx:.4g}), dx={self.dx!r}, "
                f"dim={self.dim}, J={self.J!r})")

    @property
    def h_over_dx_paper(self):
        """The paper's ratio ``h_B / dx_r`` (2 for BIPI2D's defaults)."""
        return self.h_b / self.dx

    # -- objective ------------------------------------------------------------------
    def energies(self, w_p, gamma_p):
        """Per-particle ``E_BI``: ``(V/2) sum_{b != a} W_ab - gamma_a`` (``w_p`` includes b = a)."""
        return 0.5 * self.volume * (w_p - self.kernel.w0(self.h)) - gamma_p

    def gradient(self, grad_w_pc, grad_gamma_pc):
        """``dE_BI / dx_a = V sum_b grad_a W_ab - grad gamma_a`` (= gamma_a grad C_a)."""
        return self.volume * grad_w_pc - grad_gamma_pc

    # -- concentration (Eq. 4-5) ----------------------------------------------------
    def concentration(self, w_p, gamma_p):
        """``C_a = V sum_b W_ab / gamma_a`` (Eq. 4)."""
        return self.volume * w_p / gamma_p

    def concentration_gradient(self, grad_w_pc, grad_gamma_pc, gamma_p):
        """``grad C_a`` (Eq. 5)."""
        return self.gradient(grad_w_pc, grad_gamma_pc) / gamma_p[:, None]

    # -- the packer's shift (Eq. 14-15) -----------------------------------------------
    def shift(self, grad_c_pc, near_pc, gamma_p, pressure=True):
        """Displacements of Eq. 14 (step boundary pressure) capped by Eq. 15.

        Parameters
        ----------
        grad_c_pc : (N, 3)
            ``grad C_a``.
        near_pc : (N, 3)
            ``sum grad gamma_as`` over the elements whose line/plane is within ``band`` of a.
        gamma_p : (N,)
        pressure : bool
            False gives Eq. 12 (no boundary pressure).
        """
        # the same operations as -D (grad C - (0.5 / gamma) near), in one (N, 3) array
        if pressure:
            step = np.multiply((0.5 / gamma_p)[:, None], near_pc)
            np.subtract(grad_c_pc, step, out=step)
            step *= -self.diffusion
        else:
            step = -self.diffusion * grad_c_pc
        norm = np.sqrt(np.einsum("pc,pc->p", step, step))
        over = norm > self.cap
        step[over] *= (self.cap / norm[over])[:, None]
        return step

    def wall_gamma(self, distance):
        """``gamma`` at ``distance`` from a straight wall (2D) or a plane (3D): Step 2b's threshold.

        From the same boundary integrals as the particles' ``gamma`` (a square or cube of side
        ``8 h`` with the point above the middle of one side).
        """
        from ..boundary import BoundarySegments, BoundaryTriangles, gamma_and_gradient

        size = 4.0 * self.h
        if self.dim == 2:
            wall = BoundarySegments.from_vertices([[-size, 0.0], [size, 0.0], [size, 2 * size], [-size, 2 * size]])
            point = [[0.0, distance, 0.0]]
        else:
            import trimesh

            box = trimesh.creation.box(extents=(2 * size, 2 * size, 2 * size))
            box.apply_translation([0.0, 0.0, size])
            wall = BoundaryTriangles.from_trimesh(box)
            point = [[0.1 * self.h, 0.2 * self.h, distance]]  # off the bottom face's diagonal
        return float(gamma_and_gradient(point, wall, self.h, self.kernel.name)[0][0])
