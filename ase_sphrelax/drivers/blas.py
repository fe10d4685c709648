"""BLAS threads against numba threads in the optimisers (issue 9, item 4).

ASE's optimisers do their vector work in numpy: LBFGS's two-loop recursion is a few dozen
dot products of length 3N per step, FIRE's mixing two ``vdot``; BFGS diagonalises its
Hessian. Multi-threaded OpenBLAS collapses when another process holds a core: measured on
this project's 2-vCPU machines, 1000 ``np.dot`` of length 24672 took 0.615 s with 2 OpenBLAS
threads and 0.0088 s with one, and 100 LBFGS steps on the default circle 12.0 s against
1.04 s. The parallel part of a step is the force evaluation, which runs on numba's
threads; the optimiser's vectors are too short to gain from BLAS threads. So the drivers
run each optimiser step with BLAS limited to one thread (threadpoolctl), unless the user
chose a BLAS thread count (``OPENBLAS_NUM_THREADS`` and friends in the environment, or an
explicit ``blas_threads``): their own setting is kept.
"""
from __future__ import annotations

import functools
import os

__all__ = ["BLAS_THREAD_VARIABLES", "user_blas_threads", "resolve_blas_threads", "limit_blas_in_steps"]

# environment variables by which a user sets the BLAS / OpenMP thread count
BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "GOTO_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS",
                         "BLIS_NUM_THREADS", "VECLIB_MAXIMUM_THREADS")

_CONTROLLER = None


def user_blas_threads():
    """The BLAS thread variables the user set in the environment, as a dict (empty if none)."""
    return {name: os.environ[name] for name in BLAS_THREAD_VARIABLES if os.environ.get(name, "").strip()}


def resolve_blas_threads(blas_threads=None):
    """BLAS thread limit to apply in optimiser steps, or None to leave BLAS alone.

    Parameters
    ----------
    blas_threads : None, False or int >= 1
        None: 1, unless the user set a BLAS thread variable (then None: their setting is kept).
        False: never limit. An integer: that limit.
    """
    if blas_threads is False:
        return None
    if blas_threads is None:
        return None if user_blas_threads() else 1
    if isinstance(blas_threads, bool) or not isinstance(blas_threads, int) or blas_threads < 1:
        raise ValueError(f"blas_threads must be None, False or an integer >= 1, got {blas_threads!r}")
    return int(blas_threads)


def _controller():
    """One threadpoolctl controller (it inspects the loaded libraries once)."""
    global _CONTROLLER
    if _CONTROLLER is None:
        import numpy  # noqa: F401  (numpy's BLAS must be loaded before the libraries are listed)
        from threadpoolctl import ThreadpoolController

        _CONTROLLER = ThreadpoolController()
    return _CONTROLLER


def limit_blas_in_steps(optimizer, blas_threads=None):
    """Make ``optimizer.step`` run with BLAS limited to :func:`resolve_blas_threads` threads.

    The limit holds only inside each step (the optimiser's vector work); the previous
    setting is restored after it, so force evaluations, observers and the caller's own code
    see the user's setting. Sets ``optimizer.blas_threads`` (None when BLAS is left alone).
    Returns the optimiser.
    """
    limit = resolve_blas_threads(blas_threads)
    optimizer.blas_threads = limit
    if limit is None:
        return optimizer
    controller = _controller()
    step = optimizer.step

    @functools.wraps(step)
    def step_with_limited_blas(*args, **kwargs):
        with controller.limit(limits=limit, user_api="blas"):
            return step(*args, **kwargs)

    optimizer.step = step_with_limited_blas
    return optimizer
