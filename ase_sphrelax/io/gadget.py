"""GADGET-4 initial conditions in its HDF5 format (``ICFormat 3``), written with ``h5py``.

Layout (GADGET-4 documentation, "Snapshot file format", HDF5 section and header table): a
``Header`` group of attributes and one group per particle type, here ``PartType0`` (gas), the
group name GADGET-4 reads and writes (its text says ``ParticleType0``, its code
``snap_io::get_datagroup_name`` writes ``/PartType%d``; SWIFT, pynbody and yt read the same):

==========================  ===================================================================
``Header`` attribute        value
==========================  ===================================================================
``NumPart_ThisFile``        [N, 0, 0, 0, 0, 0] (one file)
``NumPart_Total``           [N, 0, 0, 0, 0, 0]
``NumPart_Total_HighWord``  zeros (GADGET-2/3 readers; N < 2^32 here)
``MassTable``               zeros: every gas particle has its own mass in ``Masses``
``Time``, ``Redshift``      0 (GADGET-4 takes ``TimeBegin`` from its parameter file)
``BoxSize``                 the largest box side (see below)
``NumFilesPerSnapshot``     1
``Flag_*``                  ``Flag_DoublePrecision`` 1, the others 0
``Omega0``, ...             0, ``HubbleParam`` 1 (a non-cosmological run)
==========================  ===================================================================

``PartType0`` holds ``Coo rdinates`` and ``Velocities`` (N, 3), ``ParticleIDs`` (uint64, from
1), ``Masses``, ``InternalEnergy`` (zeros when unknown: GADGET-4 then sets the temperature from
``InitGasTemp``, as its d ocumentation allows), ``SmoothingLength`` and, when known, ``Density``;
all floats in double precision (GADGET-4 converts on reading).

Smoothing length
----------------
GADGET's ``SmoothingLength`` is the kernel **support** radius ``H`` (its kernels vanish at
``r = h_GADGET``; SWIFT's  kernel notes, ``theory/SPH/Kernels``: "H is the kernel's support radius
and is used as the smoothing length in the Gadget code"), i.e. this package's ``h`` unchanged:

=====================  ========================
this package           GADGET-4 HDF5
=====================  ========================
support ``H`` = ``h``  ``SmoothingLength = H``
=====================  ========================

(GADGET-4 recomputes it from ``DesNumNgb`` at start-up; the initial-conditions reader ignores it.)

Box and dimensions
------------------
GADGET-4's box is a cube of side ``BoxSize``; a periodic box with shorter sides is compiled with
``LONG_X_BITS`` / ``LONG_ Y_BITS`` / ``LONG_Z_BITS`` (side = ``BoxSize / 2^bits``). ``BoxSize`` is the
largest used side; the bits each used axis needs are recorded as ``Header/ase_sphrelax_long_bits``,
and a periodic side that is not ``BoxSize / 2^k`` is refused. 1D and 2D runs (``ONEDIMS``,
``TWODIMS``) keep (N, 3)  coordinates with the unused components 0; ``Header/ase_sphrelax_dim``
records the dimension, ``ase_sphrelax_box`` the three sides and ``ase_sphrelax_shift`` the shift
of :func:`ase_sphrelax.io.particles.box_frame` (coordinates = positions - shift, wrapped).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .particles import all_or_none_periodic, box_frame, collect, require, single_fluid, written_atomically

__all__ = ["write_gadget", "long_bits"]

N_TYPES = 6


def long_bits(box_c, dim, periodic):
    """``(BoxSize, bits)``: the largest used side and the ``LONG_*_BITS`` of each axis.

    Raises ValueError for a periodic side that is not ``BoxSize / 2^k``.
    """
    box_size = float(np.max(box_c[:dim]))
    bits_c = np.zeros(3, dtype=int)
    for k in range(dim):
        ratio = box_size / box_c[k]
        bits = int(round(np.log2(ratio)))
        if abs(ratio - 2.0**bits) > 1e-12 * ratio:
            if periodic:
                raise ValueError(f"GADGET-4's periodic box has sides BoxSize / 2^k (LONG_{'XYZ'[k]}_BITS), but the "
                                 f"{'xyz'[k]} side is {box_c[k]:.12g} against BoxSize {box_size:.12g}: "
                                 "use a cell whose side ratios are powers of 2")
            bits = 0
        bits_c[k] = bits
    return box_size, bits_c


def write_gadget(atoms, path, *, dim=None, margin=None, thickness=1.0, **sources):
    """Write ``atoms`` as GADGET-4 HDF5 initial conditions (see the module docstring).

    Parameters are those of :func:`ase_sphrelax.io.swift.write_swift` without ``units`` and
    ``kernel`` (GADGET's smoothing length is the support itself).

    Returns
    -------
    Path

    Raises
    ------
    ValueError
        Before anything is written: no masses, NaN, a dimension that disagrees with the geometry,
        particle types other than fluid, mixed periodicity, a periodic side not BoxSize / 2^k.
    """
    particles = collect(atoms, dim, **sources)
    require(particles, "GADGET-4", m_p=True)
    single_fluid(particles, "GADGET-4")
    periodic = all_or_none_periodic(particles, "GADGET-4")
    frame = box_frame(particles, margin=margin, thickness=thickness)
    box_size, bits_c = long_bits(frame.box_c, particles.dim, periodic)
    n = len(particles)
    counts = np.zeros(N_TYPES, dtype=np.uint64)
    counts[0] = n
    header = {
        "NumPart_ThisFile": counts, "NumPart_Total": counts, "NumPart_Total_HighWord": np.zeros(N_TYPES, np.uint32),
        "MassTable": np.zeros(N_TYPES), "Time": 0.0, "Redshift": 0.0, "BoxSize": box_size,
        "NumFilesPerSnapshot": np.int32(1), "Omega0": 0.0, "OmegaBaryon": 0.0, "OmegaLambda": 0.0,
        "HubbleParam": 1.0, "Flag_Sfr": np.int32(0), "Flag_Cooling": np.int32(0), "Flag_StellarAge": np.int32(0),
        "Flag_Metals": np.int32(0), "Flag_Feedback": np.int32(0), "Flag_Entropy_ICs": np.int32(0),
        "Flag_DoublePrecision": np.int32(1), "Flag_IC_Info": np.int32(0),
        "ase_sphrelax_dim": np.int32(particles.dim), "ase_sphrelax_box": frame.box_c,
        "ase_sphrelax_shift": frame.shift_c, "ase_sphrelax_long_bits": bits_c.astype(np.int32),
        "ase_sphrelax_pbc": particles.pbc_c.astype(np.int8),
    }
    fields = {"Coordinates": frame.r_pc, "Velocities": particles.v_pc,
              "ParticleIDs": np.arange(1, n + 1, dtype=np.uint64), "Masses": particles.m_p,
              "InternalEnergy": np.zeros(n) if particles.u_p is None else particles.u_p}
    if particles.support_p is not None:
        fields["SmoothingLength"] = particles.support_p
    if particles.rho_p is not None:
        fields["Density"] = particles.rho_p

    import h5py

    path = Path(path)
    with written_atomically(path) as partial:
        with h5py.File(partial, "w") as handle:
            group = handle.create_group("Header")
            for name, value in header.items():
                group.attrs[name] = value
            gas = handle.create_group("PartType0")
            for name, values in fields.items():
                gas.create_dataset(name, data=values)
    return path
