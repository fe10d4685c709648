"""Read LAMMPS custom text dumps (``dump custom`` with the columns ``id type x y z [vx vy vz] [fx fy fz]``)."""
from __future__ import annotations

import numpy as np
from ase import Atoms
from ase.calculators.singlepoint import SinglePointCalculator

__all__ = ["read_dump", "read_dump_frames"]


def _parse_frames(path):
    with open(path) as fh:
        lines = fh.read().splitlines()
    frames = []
    i = 0
    while i < len(lines):
        if not lines[i].startswith("ITEM: TIMESTEP"):
            i += 1
            continue
        step = int(lines[i + 1].split()[0])
        assert lines[i + 2].startswith("ITEM: NUMBER OF ATOMS"), f"{path}: malformed dump near line {i + 3}"
        n = int(lines[i + 3])
        head = lines[i + 4]
        if not head.startswith("ITEM: BOX BOUNDS"):
            raise ValueError(f"{path}: expected 'ITEM: BOX BOUNDS' at line {i + 5}")
        tokens = head.split()[3:]
        tilted = tokens[:3] == ["xy", "xz", "yz"]
        flags = tokens[3:] if tilted else tokens
        bounds = np.array([[float(x) for x in lines[i + 5 + k].split()] for k in range(3)])
        cols = lines[i + 8].split()[2:]
        data = np.array([row.split() for row in lines[i + 9 : i + 9 + n]], dtype=float).reshape(n, len(cols))
        frames.append((step, tilted, flags, bounds, cols, data))
        i += 9 + n
    if not frames:
        raise ValueError(f"{path} holds no LAMMPS dump frame")
    return frames


def _frame_to_atoms(frame, dim, reference):
    step, tilted, flags, bounds, cols, data = frame
    if tilted:
        xy, xz, yz = bounds[:, 2]
        xlo = bounds[0, 0] - min(0.0, xy, xz, xy + xz)
        xhi = bounds[0, 1] - max(0.0, xy, xz, xy + xz)
        ylo = bounds[1, 0] - min(0.0, yz)
        yhi = bounds[1, 1] - max(0.0, yz)
        zlo, zhi = bounds[2, :2]
    else:
        xy = xz = yz = 0.0
        (xlo, xhi), (ylo, yhi), (zlo, zhi) = bounds[:, :2]
    cell = np.array([[xhi - xlo, 0, 0], [xy, yhi - ylo, 0], [xz, yz, zhi - zlo]])
    lo = np.array([xlo, ylo, zlo])
    index = {c: k for k, c in enumerate(cols)}
    if "id" not in index:
        raise ValueError("the dump needs an 'id' column")
    order = np.argsort(data[:, index["id"]])
    data = data[order]

    def block(names):
        return np.stack([data[:, index[c]] for c in names], axis=1)

    if all(c in index for c in "xyz"):
        r_pc = block("xyz")
    elif all(c in index for c in ("xu", "yu", "zu")):
        r_pc = block(("xu", "yu", "zu"))
    elif all(c in index for c in ("xs", "ys", "zs")):
        r_pc = block(("xs", "ys", "zs")) @ cell + lo
    else:
        raise ValueError(f"the dump needs x y z (or xu yu zu, xs ys zs) columns, has {cols}")
    pbc = np.array([f.startswith("p") for f in flags[:3]])
    if dim is None:
        flat = pbc[2] and np.all(r_pc[:, 2] == 0) and xz == 0 and yz == 0
        dim = 2 if flat and abs(zlo + zhi) <= 1e-12 * max(1.0, zhi - zlo) else 3
    rot_cc = np.eye(3)
    if reference is not None:
        from .box import lammps_box  # noqa: PLC0415

        rot_cc = lammps_box(reference, dim=dim, margin=0.0).rot_cc
    v_pc = block(("vx", "vy", "vz")) if all(c in index for c in ("vx", "vy", "vz")) else None
    f_pc = block(("fx", "fy", "fz")) if all(c in index for c in ("fx", "fy", "fz")) else None
    r_pc = r_pc @ rot_cc.T
    if dim == 2:
        pbc[2] = False
        cell[2] = (0.0, 0.0, 1.0)
        r_pc[:, 2] = 0.0
    numbers = np.zeros(len(data), int)
    atoms = Atoms(numbers=numbers, positions=r_pc, cell=cell @ rot_cc.T, pbc=pbc)
    if reference is not None:
        atoms.set_cell(reference.cell, scale_atoms=False)
        atoms.pbc = reference.pbc
        atoms.numbers = reference.numbers
    if "type" in index:
        atoms.arrays["type"] = data[:, index["type"]].astype(int)
    atoms.arrays["id"] = data[:, index["id"]].astype(int)
    if v_pc is not None:
        atoms.set_velocities(v_pc @ rot_cc.T)
    for extra in ("rho", "esph", "cv", "c_pe", "c_ke"):
        if extra in index:
            atoms.arrays[extra] = data[:, index[extra]].copy()
    atoms.info["timestep"] = step
    if f_pc is not None:
        atoms.calc = SinglePointCalculator(atoms, forces=f_pc @ rot_cc.T)
    return atoms


def read_dump(path, index=-1, dim=None, reference=None):
    """Read one frame of a LAMMPS custom text dump as :class:`ase.Atoms`.

    Parameters
    ----------
    path : str or Path
        Dump written with ``dump ... custom ... id type x y z [vx vy vz] [fx fy fz]``.
    index : int
        Frame (default: the last one).
    dim : {2, 3, None}
        2 gives the ASE 2D convention (z = 0, pbc[2] False, c = (0, 0, 1));
        None guesses 2 for a periodic z slab centred on 0 with all z = 0.
    reference : ase.Atoms or None
        The set the run started from: positions, velocities and forces are
        rotated back into its frame and its cell, pbc and numbers are copied.

    Returns
    -------
    ase.Atoms
        Sorted by id; ``arrays['type']``, ``arrays['id']``, velocities, and forces
        (through a SinglePointCalculator) when the dump has them.
    """
    frames = _parse_frames(path)
    return _frame_to_atoms(frames[index], dim, reference)


def read_dump_frames(path, dim=None, reference=None):
    """All frames of a dump as a list of :class:`ase.Atoms`."""
    return [_frame_to_atoms(f, dim, reference) for f in _parse_frames(path)]
