"""Whitened coordinates for SPH-ParVI: the fluid runs in ``y = L^-1 (x - c)`` (issue 18, item 1).

An affine map ``x = c + L y`` (``L`` invertible) carries the target p on x to its pull-back on y,
``p_y(y) = p(c + L y) |det L|`` (theory.py, eq. W1), with score ``s_y(y) = L^T s(c + L y)`` (eq. W2).
The SPH fluid, its isotropic kernels, adaptive supports, CFL step and friction all live in y: with
``L`` the Cholesky factor of the particles' covariance the fluid sees a target of unit covariance
whatever p's linear correlations and scales, so its cost is affine invariant (as emcee's).

For a fixed map the isothermal fluid at rest in y has density ``p_y`` (the default configuration's
result applied to ``p_y``), so the particles mapped back by ``x = c + L y`` have density p: exact.
When the map changes, the state is carried over exactly (positions ``y' = L'^-1 (c + L y - c')``,
velocities ``v' = L'^-1 L v``), but a fluid at rest under one map is not at rest under another
(its particle arrangement is isotropic in the old y). :class:`ParVISampler` therefore updates the map
at intervals in the first part of the run only and holds it fixed afterwards, the part in which the
convergence is judged (see ``whiten_until``).
"""
from __future__ import annotations

import numpy as np

__all__ = ["AffineMap", "check_whiten"]


class AffineMap:
    """``x = c + L y`` with ``centre_c`` (d,) and ``l_cc`` (d, d); row-vector arrays ``(M, d)``."""

    def __init__(self, centre_c, l_cc):
        self.set(centre_c, l_cc)

    def set(self, centre_c, l_cc):
        self.centre_c = np.array(centre_c, dtype=float)
        self.l_cc = np.array(l_cc, dtype=float)
        self.l_inv_cc = np.linalg.inv(self.l_cc)
        self.log_det = float(np.linalg.slogdet(self.l_cc)[1])

    def to_x(self, y_pc):
        return self.centre_c + y_pc @ self.l_cc.T

    def to_y(self, x_pc):
        return (x_pc - self.centre_c) @ self.l_inv_cc.T

    def log_density_y(self, log_density):
        """``log p_y(y) = log p(c + L y) + log |det L|`` (eq. W1)."""
        return lambda y_pc: log_density(self.to_x(y_pc)) + self.log_det

    def score_y(self, score):
        """``s_y(y) = L^T s(c + L y)`` (eq. W2), rows: ``s(x_pc) @ L``."""
        return lambda y_pc: score(self.to_x(y_pc)) @ self.l_cc

    def renew(self, y_pc, v_pc, rho_p=None):
        """Set the map to the particles' mean and Cholesky covariance factor; carry the state over exactly.

        Returns ``(y', v', rho')`` in the new coordinates (``rho`` scales with ``|det L'| / |det L|``);
        keeps the old map (and returns the state unchanged) when the covariance is not positive definite.
        """
        x_pc = self.to_x(y_pc)
        cov_cc = np.atleast_2d(np.cov(x_pc, rowvar=False))
        try:
            new_l_cc = np.linalg.cholesky(cov_cc)
        except np.linalg.LinAlgError:
            return y_pc, v_pc, rho_p
        if not np.all(np.isfinite(new_l_cc)) or np.linalg.cond(new_l_cc) > 1e12:
            return y_pc, v_pc, rho_p
        old_l_cc, old_log_det = self.l_cc, self.log_det
        self.set(x_pc.mean(axis=0), new_l_cc)
        v_new = v_pc @ old_l_cc.T @ self.l_inv_cc.T
        rho_new = None if rho_p is None else rho_p * np.exp(self.log_det - old_log_det)
        return self.to_y(x_pc), v_new, rho_new


def check_whiten(whiten, dim):
    """``None``, ``"covariance"`` or an invertible (dim, dim) matrix L; a one-line error otherwise."""
    if whiten is None or (isinstance(whiten, str) and whiten == "covariance"):
        return whiten
    if isinstance(whiten, str):
        raise ValueError(f"whiten must be None, 'covariance' or an invertible (dim, dim) matrix, got {whiten!r}")
    l_cc = np.array(whiten, dtype=float)
    if l_cc.shape != (dim, dim) or not np.all(np.isfinite(l_cc)) or np.linalg.cond(l_cc) > 1e12:
        raise ValueError(f"whiten must be None, 'covariance' or a finite invertible ({dim}, {dim}) matrix, "
                         f"got an array of shape {l_cc.shape}")
    return l_cc
