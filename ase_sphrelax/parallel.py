"""One threading model for the hot loops: numba ``nogil`` functions over static chunks.

Every parallel loop of the package (pair loops, neighbour-list passes, gathers and folds)
is a serial numba function compiled with ``nogil=True`` that works on the points
``[first, last)``; :func:`run_chunks` runs one chunk per thread: the calling thread
takes the last chunk, a persistent thread pool the others. Only one threading model is used because mixing them costs: after a numba
``prange`` loop its OpenMP workers spin for a while and take a core from the next
loop's threads (measured: a pair loop at 2 threads ran at the speed of 1).

Systems below :data:`PARALLEL_MIN` points run serially: waking threads costs more than
the work (measured: 400 particles, 16 ms parallel vs 0.1 ms serial under load). The
thread count follows ``numba.get_num_threads()`` (``numba.set_num_threads`` or
``NUMBA_NUM_THREADS``).
"""
from __future__ import annotations

import numba
import numpy as np

__all__ = ["PARALLEL_MIN", "thread_count", "thread_pool", "chunk_bounds", "run_chunks", "reduce_chunks",
           "copy_rows"]

PARALLEL_MIN = 20000

_POOLS: dict = {}


def thread_count(n_points):
    """Threads used for a loop over ``n_points`` points (1 below ``PARALLEL_MIN``)."""
    return numba.get_num_threads() if n_points >= PARALLEL_MIN else 1


def thread_pool(nthreads):
    """The persistent pool of ``nthreads`` worker threads (created on first use)."""
    if nthreads not in _POOLS:
        from concurrent.futures import ThreadPoolExecutor

        _POOLS[nthreads] = ThreadPoolExecutor(max_workers=nthreads, thread_name_prefix="ase_sphrelax")
    return _POOLS[nthreads]


def chunk_bounds(n, nthreads):
    """The static chunks ``[(first, last), ...]`` of ``range(n)`` on ``nthreads`` threads."""
    chunk = (n + nthreads - 1) // nthreads
    return [(min(n, t * chunk), min(n, (t + 1) * chunk)) for t in range(nthreads)]


def run_chunks(loop, n, args, per_thread=None, nthreads=None):
    """Call ``loop(*args, *per_thread[t], first, last)`` on ``nthreads`` static chunks of ``range(n)``.

    Parameters
    ----------
    loop : numba dispatcher compiled with ``nogil=True``
    n : int
        Number of points.
    args : tuple
        Arguments shared by every chunk.
    per_thread : list of tuples or None
        Extra arguments of each thread (e.g. its own output buffers); its length sets
        the number of threads.
    nthreads : int or None
        Number of threads when ``per_thread`` is None (default :func:`thread_count`).
    """
    if per_thread is not None:
        nthreads = len(per_thread)
    elif nthreads is None:
        nthreads = thread_count(n)
    extra = per_thread if per_thread is not None else [()] * nthreads
    if nthreads == 1:
        return loop(*args, *extra[0], 0, n)
    bounds = chunk_bounds(n, nthreads)
    pool = thread_pool(nthreads)
    # the calling thread runs the last chunk itself: one thread fewer to wake per loop
    jobs = [pool.submit(loop, *args, *extra[t], *bounds[t]) for t in range(nthreads - 1)]
    try:
        loop(*args, *extra[-1], *bounds[-1])
    finally:
        for job in jobs:
            job.result()
    return None


def reduce_chunks(loop, n, args, nout, fill=0.0):
    """Call ``loop(*args, out, first, last)`` on :func:`thread_count` static chunks of ``range(n)``, each thread
    with its own ``out`` (``nout`` floats set to ``fill``) that the loop combines its chunk's values into (a sum,
    a max, an and); returns the per-thread ``out`` arrays, to be combined by the caller."""
    outs = [np.full(nout, fill) for _ in range(thread_count(n))]
    run_chunks(loop, n, args, per_thread=[(out,) for out in outs])
    return outs


@numba.njit(cache=True, nogil=True)
def _copy_rows_chunk(dst, src, first, last):
    for p in range(first, last):
        for c in range(dst.shape[1]):
            dst[p, c] = src[p, c]


def copy_rows(dst, src):
    """``dst[:] = src`` for two arrays of one shape (P, C) or (P,) and one dtype (float64 or int64 in chunks), the
    rows in :func:`thread_count` chunks (at 1e6 particles numpy's single-threaded copy of positions costs 3.5 ms; in
    place, no new pages)."""
    if dst.shape != src.shape or dst.ndim not in (1, 2):
        raise ValueError(f"copy_rows: shapes must be equal (P, C) or (P,), got {dst.shape} and {src.shape}")
    if thread_count(dst.shape[0]) == 1 or dst.dtype != src.dtype or dst.dtype not in (np.float64, np.int64) \
            or not (dst.flags.c_contiguous and src.flags.c_contiguous):
        dst[...] = src
        return
    if dst.ndim == 1:
        dst, src = dst.reshape(-1, 1), src.reshape(-1, 1)
    run_chunks(_copy_rows_chunk, dst.shape[0], (dst, src))
