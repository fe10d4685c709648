"""Particle files for other simulators: SWIFT and GADGET-4 initial conditions, VTU for ParaView.

* :mod:`.particles` — the per-particle arrays of an ``Atoms`` (masses, support radii, densities,
  internal energies, types, cell, periodicity, dimension) and the ``[0, L)`` frame of the box codes;
* :mod:`.swift` — SWIFT initial conditions through ``swiftsimio`` (``h = H / gamma_K``);
* :mod:`.gadget` — GADGET-4 HDF5 initial conditions through ``h5py`` (``SmoothingLength = H``);
* :mod:`.vtu` — VTU point data through ``meshio``.

The libraries are the optional extra ``export`` (``pip install ase-sphrelax[export]``), imported
when a file is written. ``sphrelax export`` (``lammps_io.cli``) dispatches to these writers.
"""
from ..lazy import lazy_exports

_WHERE = {
    "ParticleArrays": ".particles",
    "collect": ".particles",
    "box_frame": ".particles",
    "write_swift": ".swift",
    "swift_smoothing_length": ".swift",
    "SWIFT_KERNEL_GAMMA": ".swift",
    "SWIFT_UNITS": ".swift",
    "write_gadget": ".gadget",
    "write_vtu": ".vtu",
}
__all__ = list(_WHERE)
__getattr__, __dir__ = lazy_exports(globals(), _WHERE, submodules=("particles", "swift", "gadget", "vtu"))
