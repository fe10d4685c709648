"""SWIFT initial conditions (HDF5) through ``swiftsimio``'s ``Writer``.

The file layout is SWIFT's (docs ``InitialConditions/index.rst``): ``Header`` (``BoxSize``,
``NumPart_Total``, ``NumPart_ThisFile``, ``MassTable``, ``Dimension``, ...), ``Units``,
``RuntimePars/PeriodicBoundariesOn`` and ``PartType0`` (gas) with ``Coordinates``,
``Velocities``, ``Masses``, ``SmoothingLength``, ``InternalEnergy``, ``ParticleIDs`` (from 1)
and, when the particles carry them, ``Densities``. Everything is written in double precision.

Smoothing length
----------------
SWIFT writes ``W(r, h) = C / H^d f(r / H)`` with ``H = gamma_K h`` (docs
``HydroSchemes/kernels.rst``; ``kernel_gamma`` in ``src/kernel_hydro.h``, after Table 1 of
Dehnen & Aly 2012): its ``SmoothingLength`` is ``h = H / gamma_K``, where ``H`` is the kernel
support, the ``h`` of this package. The ratio depends on the kernel SWIFT is configured with
(``--with-kernel``) and on the dimension:

==================  =========  =========  =========
SWIFT kernel        1D         2D         3D
==================  =========  =========  =========
``cubic-spline``    1.732051   1.778002   1.825742
``quartic-spline``  1.936492   1.977173   2.018932
``quintic-spline``  2.121321   2.158131   2.195775
``wendland-C2``     1.620185   1.897367   1.936492
``wendland-C4``     (none)     2.171239   2.207940
``wendland-C6``     (none)     2.415230   2.449490
==================  =========  =========  =========

So a support ``H = 0.2`` in 1D with SWIFT's default cubic spline is written as
``h = 0.2 / 1.732051 = 0.11547``; with ``wendland-C2`` in 3D as ``0.2 / 1.936492 = 0.10328``.
SWIFT has no 1D Wendland C4/C6 (its build stops with an error): asking for them is an error here.
To start SWIFT with the kernel a set was relaxed with (ALARIC: Wendland C4 in 2D/3D; Fan, BIPI:
Wendland C2), configure SWIFT ``--with-kernel=wendland-C4`` (``-C2``) and pass the same ``kernel``:
the support radii then carry over exactly.
The kernel and its ratio are recorded in the header (``ase_sphrelax_kernel``,
``ase_sphrelax_kernel_gamma``).

Dimensions
----------
SWIFT stores 1D and 2D runs like 3D ones (its ``SodShock_1D``/``_2D`` examples): ``Coordinates``
and ``Velocities`` of shape (N, 3) with the unused components 0, a three-component ``BoxSize``
(the unused sides ``thickness``, default 1), and ``Header/Dimension`` = 1, 2 or 3, which SWIFT
checks against the dimension it was compiled for.

Units (``units=``)
------------------
The numbers are not converted: they are taken to be in the base units of the named system, which
the ``Units`` group records (SWIFT converts to its internal units on reading):

============  ============================================================
``cgs``       cm, g, s
``si``        m, kg, s
``galactic``  kpc, Msun, Myr
``cosmo``     Mpc, 1e10 Msun, Mpc/(km/s) (swiftsimio's ``cosmo_units``)
============  ============================================================

Positions are moved into ``[0, L)`` by :func:`ase_sphrelax.io.particles.box_frame`; the shift is
recorded as ``Header/ase_sphrelax_shift`` (coordinates in the file = positions - shift, wrapped).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .particles import all_or_none_periodic, box_frame, collect, require, single_fluid, written_atomically

__all__ = ["write_swift", "SWIFT_KERNEL_GAMMA", "SWIFT_UNITS", "swift_smoothing_length"]

#: gamma_K = H / h of SWIFT's kernels by dimension (src/kernel_hydro.h; Dehnen & Aly 2012, Table 1)
SWIFT_KERNEL_GAMMA = {
    "cubic-spline": {1: 1.732051, 2: 1.778002, 3: 1.825742},
    "quartic-spline": {1: 1.936492, 2: 1.977173, 3: 2.018932},
    "quintic-spline": {1: 2.121321, 2: 2.158131, 3: 2.195775},
    "wendland-C2": {1: 1.620185, 2: 1.897367, 3: 1.936492},
    "wendland-C4": {2: 2.171239, 3: 2.207940},
    "wendland-C6": {2: 2.415230, 3: 2.449490},
}

#: the unit systems of ``units=``: their base length, mass and time
SWIFT_UNITS = {"cgs": "cm, g, s", "si": "m, kg, s", "galactic": "kpc, Msun, Myr",
               "cosmo": "Mpc, 1e10 Msun, Mpc/(km/s)"}


def swift_smoothing_length(support, kernel, dim):
    """SWIFT's ``h = H / gamma_K`` for the support radius ``H`` (see the module's table)."""
    if kernel not in SWIFT_KERNEL_GAMMA:
        raise ValueError(f"kernel must be one of SWIFT's {sorted(SWIFT_KERNEL_GAMMA)}, got {kernel!r}")
    if dim not in SWIFT_KERNEL_GAMMA[kernel]:
        raise ValueError(f"SWIFT has no {dim}D {kernel} kernel: choose one of "
                         f"{sorted(k for k, by_dim in SWIFT_KERNEL_GAMMA.items() if dim in by_dim)}")
    return np.asarray(support, dtype=float) / SWIFT_KERNEL_GAMMA[kernel][dim]


def _unit_system(units):
    import unyt

    if units == "cosmo":
        from swiftsimio.metadata.writer.unit_systems import cosmo_units

        return cosmo_units
    registry = {"cgs": "cgs", "si": "mks", "galactic": "galactic"}
    if units not in registry:
        raise ValueError(f"units must be one of {sorted(SWIFT_UNITS)}, got {units!r}")
    return unyt.unit_systems.unit_system_registry[registry[units]]


def _dataset_attributes(unit_system, dimension, a_exponent):
    """The unit attributes swiftsimio writes on its own datasets, for an extra dataset."""
    import unyt
    from unyt.dimensions import current_mks, length, mass, temperature, time

    from swiftsimio.snapshot_writer import get_dimensions

    cgs = float(unyt.unyt_quantity(1.0, unit_system[dimension]).in_cgs().v)
    exponents = get_dimensions(dimension)
    return {"Conversion factor to CGS (not including cosmological corrections)": [cgs],
            "Conversion factor to physical CGS (including cosmological corrections)": [cgs],
            "U_I exponent": [exponents[current_mks]], "U_L exponent": [exponents[length]],
            "U_M exponent": [exponents[mass]], "U_T exponent": [exponents[temperature]],
            "U_t exponent": [exponents[time]], "a-scale exponent": [float(a_exponent)], "h-scale exponent": [0.0]}


def write_swift(atoms, path, *, units="cgs", kernel="cubic-spline", dim=None, margin=None, thickness=1.0,
                **sources):
    """Write ``atoms`` as SWIFT initial conditions (HDF5; see the module docstring).

    Parameters
    ----------
    atoms : ase.Atoms
    path : str or Path
    units : {"cgs", "si", "galactic", "cosmo"}
        The unit system the numbers are in (recorded, not converted).
    kernel : str
        SWIFT's kernel (``--with-kernel``), which sets ``h = H / gamma_K``.
    dim : {1, 2, 3, None}
    margin, thickness : float
        See :func:`ase_sphrelax.io.particles.box_frame`.
    **sources
        ``masses``, ``dx``, ``rho0``, ``support``, ``internal_energy``, ``cs2``, ``gamma`` of
        :func:`ase_sphrelax.io.particles.collect`.

    Returns
    -------
    Path

    Raises
    ------
    ValueError
        Before anything is written: no masses, support radii or internal energies, NaN, a
        dimension that disagrees with the geometry, particle types other than fluid, a mixture
        of periodic and bounded axes, an unknown kernel or unit system.
    """
    particles = collect(atoms, dim, **sources)
    require(particles, "SWIFT", m_p=True, support_p=True, u_p=True)
    single_fluid(particles, "SWIFT")
    periodic = all_or_none_periodic(particles, "SWIFT")
    h_p = swift_smoothing_length(particles.support_p, kernel, particles.dim)
    unit_system = _unit_system(units)
    frame = box_frame(particles, margin=margin, thickness=thickness)

    import h5py
    import unyt
    from swiftsimio import Writer, cosmo_array

    def comoving(values, dimension, a_exponent):
        return cosmo_array(values, unit_system[dimension], comoving=True, scale_factor=1.0,
                           scale_exponent=a_exponent)

    dims = unyt.dimensions
    n_types = 8  # swiftsimio's particle types (its NumPart arrays have this length)
    extra = {"Dimension": np.array([particles.dim]), "MassTable": np.zeros(n_types),  # per-particle masses
             "Time": np.array([0.0]), "ase_sphrelax_kernel": kernel,
             "ase_sphrelax_kernel_gamma": SWIFT_KERNEL_GAMMA[kernel][particles.dim],
             "ase_sphrelax_shift": frame.shift_c, "ase_sphrelax_pbc": particles.pbc_c.astype(np.int8)}
    writer = Writer(unit_system=unit_system, boxsize=comoving(frame.box_c, dims.length, 1), dimension=3,
                    compress=False, extra_header=extra)
    writer.gas.coordinates = comoving(frame.r_pc, dims.length, 1)
    writer.gas.velocities = comoving(particles.v_pc, dims.velocity, 0)
    writer.gas.masses = comoving(particles.m_p, dims.mass, 0)
    writer.gas.smoothing_lengths = comoving(h_p, dims.length, 1)
    writer.gas.internal_energy = comoving(particles.u_p, dims.length**2 / dims.time**2, -2)
    path = Path(path)
    with written_atomically(path) as partial:
        writer.write(str(partial))
        with h5py.File(partial, "a") as handle:
            handle.create_group("RuntimePars").attrs["PeriodicBoundariesOn"] = int(periodic)
            if particles.rho_p is not None:
                dataset = handle["PartType0"].create_dataset("Densities", data=particles.rho_p)
                for name, value in _dataset_attributes(unit_system, dims.density, -3).items():
                    dataset.attrs.create(name, value)
    return path
