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

Bounded renewals (theory.py, eq. W4): the first renewal sets the map from the initial particles; every later
one may shrink the covariance the fluid sees by at most a factor :data:`RENEWAL_MAX_SHRINK` along any direction
(the eigenvalues of the particles' covariance in the current y are raised to at least ``1/g`` before the map is
renewed); it may grow it freely. A fluid expanding from a narrow start flattens in some directions while it expands, and the
covariance of the moment made that the map (measured in 10-D at M = 100 with ``neighbours="knn"``: eigenvalues
4e-5 against 25 of the y covariance at step 50, a map whose smallest eigenvalue fell to 1e-6 - 1e-5 against the
target's 0.1; ``reproductions/parvi-highdim/``, section 5).
Every renewed map is still an invertible linear change of variables with the state carried over exactly, so
the stationary density for the final, frozen map is p (W3) whatever the bound.
"""
from __future__ import annotations

import numpy as np

__all__ = ["AffineMap", "RENEWAL_MAX_SHRINK", "check_whiten"]

#: The largest factor by which a renewal after the first may shrink the particles' covariance in the fluid's
#: coordinates along any direction (eq. W4; growth is not bounded); None: unbounded (the covariance of the moment).
RENEWAL_MAX_SHRINK = 2.0


class AffineMap:
    """``x = c + L y`` with ``centre_c`` (d,) and ``l_cc`` (d, d); row-vector arrays ``(M, d)``.

    ``renewals`` counts the renewals (:meth:`renew`); ``max_shrink`` (default :data:`RENEWAL_MAX_SHRINK`) bounds
    every renewal after the first (eq. W4).
    """

    def __init__(self, centre_c, l_cc, max_shrink="default"):
        self.set(centre_c, l_cc)
        self.renewals = 0
        self.max_shrink = RENEWAL_MAX_SHRINK if isinstance(max_shrink, str) and max_shrink == "default" \
            else max_shrink
        if self.max_shrink is not None and not self.max_shrink >= 1.0:
            raise ValueError(f"max_shrink must be None or a number >= 1, got {max_shrink!r}")

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

        After the first renewal the covariance is bounded (eq. W4): with ``C_y = U diag(w) U^T`` the particles'
        covariance in the current y, the new map is the Cholesky factor of ``L U diag(max(w, 1/g)) U^T L^T``
        (``g = max_shrink``; exactly the particles' covariance when no eigenvalue is below 1/g), so the particles'
        covariance in the new y has eigenvalues ``w / max(w, 1/g)``: 1, or the part of the shrinking beyond g.
        Returns ``(y', v', rho')`` in the new coordinates (``rho`` scales with ``|det L'| / |det L|``);
        keeps the old map (and returns the state unchanged) when the covariance is not positive definite.
        """
        x_pc = self.to_x(y_pc)
        if self.renewals == 0 or self.max_shrink is None:
            cov_cc = np.atleast_2d(np.cov(x_pc, rowvar=False))
        else:
            w_c, u_cc = np.linalg.eigh(np.atleast_2d(np.cov(y_pc, rowvar=False)))
            if not np.all(np.isfinite(w_c)):
                return y_pc, v_pc, rho_p
            clipped_cc = (u_cc * np.maximum(w_c, 1.0 / self.max_shrink)) @ u_cc.T
            cov_cc = self.l_cc @ clipped_cc @ self.l_cc.T
            cov_cc = 0.5 * (cov_cc + cov_cc.T)
        try:
            new_l_cc = np.linalg.cholesky(cov_cc)
        except np.linalg.LinAlgError:
            return y_pc, v_pc, rho_p
        if not np.all(np.isfinite(new_l_cc)) or np.linalg.cond(new_l_cc) > 1e12:
            return y_pc, v_pc, rho_p
        old_l_cc, old_log_det = self.l_cc, self.log_det
        self.set(x_pc.mean(axis=0), new_l_cc)
        self.renewals += 1
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
