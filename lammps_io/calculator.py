"""ASE calculator evaluating Fan's total error (Eq. 3.8) with LAMMPS.

The pair part runs in LAMMPS (``pair_style lepton`` or ``table``, see
:mod:`lammps_io.potential`); the constant self term ``N v0 vt W(0) - V`` and,
for a bounded ``domain``, the level-set boundary term (Eq. 3.8 last term,
force Eq. 4.4) are added in numpy.
"""
from __future__ import annotations

import ctypes
import tempfile
from pathlib import Path

import numpy as np
from ase.calculators.calculator import Calculator, all_changes

from ._library import import_lammps, new_lammps
from .boundary import boundary_energy_forces
from .box import lammps_box
from .potential import PAIR_STYLES, fan_self_energy, pair_commands

__all__ = ["FanLammpsCalculator", "fan_calculator"]


def _gather(lmp, name, n):
    """Per-atom 3-vector ordered by atom id, as an (n, 3) array (no Python float lists)."""
    data = lmp.gather_atoms(name, 1, 3)
    return np.frombuffer(data, dtype=np.float64, count=3 * n).reshape(n, 3).copy()


class FanLammpsCalculator(Calculator):
    """Fan's total error E (Eq. 3.8), forces (Eq. 3.17/4.4) and stress from LAMMPS.

    Parameters
    ----------
    h : float
        Kernel support radius.
    dx : float or None
        Particle spacing: v0 = vt = dx^dim.  None (periodic only): v0 = vt = V/N.
    dim : {1, 2, 3}
    style : {"lepton", "table"}
        Exact expression or a spline table of ``n_table`` points.
    domain : object or None
        Bounded domain with ``phi_and_normal`` and ``volume``; adds the boundary term.
    kernel : str
        Kernel name for :func:`ase_sphrelax.kernels.get_kernel`.
    nthreads : int
        OpenMP threads in LAMMPS (OPENMP package).
    skin : float or None
        Neighbour-list skin (default 0.1 h).
    reuse_neighbors : bool
        Reuse LAMMPS neighbour lists between calls: positions are moved by one
        ``fix nve/noforce`` step inside ``run 1 pre no`` (LAMMPS rebuilds only when an
        atom moved more than skin/2); otherwise every call is a ``run 0`` (full setup).
    """

    implemented_properties = ["energy", "free_energy", "forces", "stress"]
    _keys = ("h", "dx", "dim", "style", "domain", "kernel", "n_table", "nthreads", "skin", "reuse_neighbors")

    def __init__(self, h, dx=None, dim=2, style="lepton", domain=None, kernel="wendland_c2", n_table=20000,
                 nthreads=1, skin=None, reuse_neighbors=False, **kwargs):
        unknown = set(kwargs) - {"label", "atoms", "directory"}
        if unknown:
            raise TypeError(f"unknown keyword(s) {sorted(unknown)}; accepted: {self._keys}")
        if not (np.isscalar(h) and h > 0):
            raise ValueError(f"h must be a positive float, got {h!r}")
        if dx is not None and not (np.isscalar(dx) and dx > 0):
            raise ValueError(f"dx must be a positive float or None, got {dx!r}")
        if dim not in (1, 2, 3):
            raise ValueError(f"dim must be 1, 2 or 3, got {dim!r}")
        if style not in PAIR_STYLES:
            raise ValueError(f"style must be one of {PAIR_STYLES}, got {style!r}")
        if domain is not None and not hasattr(domain, "phi_and_normal"):
            raise TypeError("domain must provide phi_and_normal(r_pc) and volume")
        if not (isinstance(nthreads, (int, np.integer)) and nthreads >= 1):
            raise ValueError(f"nthreads must be an integer >= 1, got {nthreads!r}")
        import_lammps()  # fail early with the install hint
        Calculator.__init__(self, **kwargs)
        self.h = float(h)
        self.dx = None if dx is None else float(dx)
        self.dim = int(dim)
        self.style = style
        self.domain = domain
        self.kernel = kernel
        self.n_table = int(n_table)
        self.nthreads = int(nthreads)
        self.skin = 0.1 * self.h if skin is None else float(skin)
        self.reuse_neighbors = bool(reuse_neighbors)
        self._lmp = None
        self._key = None
        self._tmp = None

    def set(self, **kwargs):
        unknown = set(kwargs) - set(self._keys)
        if unknown:
            raise TypeError(f"unknown keyword(s) {sorted(unknown)}; accepted: {self._keys}")
        return Calculator.set(self, **kwargs)

    # -- LAMMPS instance -------------------------------------------------------
    def _volumes(self, atoms):
        n = len(atoms)
        periodic = all(atoms.pbc[: self.dim])
        measure = abs(float(np.linalg.det(atoms.cell[: self.dim, : self.dim]))) if periodic else None
        if self.dx is None:
            if not periodic:
                raise ValueError("dx=None needs a periodic cell (v0 = vt = V/N)")
            v0 = measure / n
        else:
            v0 = self.dx**self.dim
        if self.domain is not None:
            volume = float(self.domain.volume)
        elif periodic:
            volume = measure
        else:
            volume = n * v0
        return v0, volume, periodic

    def close(self):
        if self._lmp is not None:
            self._lmp.close()
            self._lmp = None
            self._key = None

    def __del__(self):
        try:
            self.close()
        except Exception:  # noqa: BLE001
            pass

    def _build(self, atoms, box, v0):
        self.close()
        lmp = new_lammps(nthreads=self.nthreads)
        if self._tmp is None:
            self._tmp = tempfile.TemporaryDirectory(prefix="lammps_io_")
        boundary = " ".join("p" if p else "m" for p in box.pbc)
        cmds = [
            "units lj",
            f"dimension {box.lammps_dimension}",
            f"boundary {boundary}",
            "atom_style atomic",
            "atom_modify map array",
            box.region_command(),
            "create_box 1 box",
            "mass 1 1.0",
        ]
        lmp.commands_list(cmds)
        n = len(atoms)
        lmp.create_atoms(n, list(range(1, n + 1)), [1] * n, box.r_pc.ravel().tolist())
        dxv = self.dx if self.dx is not None else v0 ** (1.0 / self.dim)
        cmds = pair_commands(self.h, dxv, self.dim, style=self.style, kernel=self.kernel,
                             table_path=Path(self._tmp.name) / "fan.table", n_table=self.n_table, v0=v0, vt=v0)
        cmds += [
            f"neighbor {self.skin:.17g} bin",
            "neigh_modify every 1 delay 0 check yes",
            "compute fanvir all pressure NULL virial",
            "thermo_style custom step pe c_fanvir[1] c_fanvir[2] c_fanvir[3] c_fanvir[4] c_fanvir[5] c_fanvir[6]",
            "thermo_modify norm no",
            # reuse mode moves atoms by v dt (no force term) inside `run 1 pre no`
            "timestep 1.0",
            "fix fanmove all nve/noforce",
        ]
        lmp.commands_list(cmds)
        self._lmp = lmp

    def calculate(self, atoms=None, properties=("energy",), system_changes=all_changes):
        Calculator.calculate(self, atoms, properties, system_changes)
        atoms = self.atoms
        n = len(atoms)
        box = lammps_box(atoms, dim=self.dim, margin=self.h)
        v0, volume, periodic = self._volumes(atoms)
        key = (n, tuple(atoms.pbc), atoms.cell[:].tobytes(), v0, box.lo_c.tobytes() if periodic else None)
        rebuilt = False
        if self._lmp is None or key != self._key:
            self._build(atoms, box, v0)
            self._key = key
            rebuilt = True
        lmp = self._lmp
        if rebuilt or not self.reuse_neighbors:
            if not rebuilt:
                x = np.ascontiguousarray(box.r_pc.ravel())
                lmp.scatter_atoms("x", 1, 3, (ctypes.c_double * (3 * n)).from_buffer(x))
            lmp.command("run 0 post no")
        else:
            # one nve/noforce step of length 1 with v = displacement: LAMMPS keeps its
            # neighbour list unless an atom moved more than skin/2 since the last build
            x_old = _gather(lmp, "x", n)
            d_pc = box.r_pc - x_old
            if periodic:
                cell_lmp = np.array([[*(box.hi_c - box.lo_c)[:1], 0, 0],
                                     [box.tilt_t[0], (box.hi_c - box.lo_c)[1], 0],
                                     [box.tilt_t[1], box.tilt_t[2], (box.hi_c - box.lo_c)[2]]])
                act = slice(0, self.dim)
                frac = np.linalg.solve(cell_lmp[act, act].T, d_pc[:, act].T).T
                d_pc[:, act] = (frac - np.round(frac)) @ cell_lmp[act, act]
            v = np.ascontiguousarray(d_pc.ravel())
            lmp.scatter_atoms("v", 1, 3, (ctypes.c_double * (3 * n)).from_buffer(v))
            lmp.command("run 1 pre no post no")
        thermo = lmp.last_thermo()
        e_pair = float(thermo["PotEng"])
        f_pc = _gather(lmp, "f", n)
        f_pc = box.to_ase(f_pc)
        energy = e_pair + fan_self_energy(n, self.h, v0 ** (1.0 / self.dim), self.dim, volume, self.kernel, v0, v0)
        if self.domain is not None:
            e_b, fb_pc = boundary_energy_forces(self.domain, atoms.positions, self.h, v0, self.dim, self.kernel)
            energy += e_b
            f_pc = f_pc + fb_pc
        if self.dim < 3:
            f_pc[:, self.dim:] = 0.0
        self.results["energy"] = energy
        self.results["free_energy"] = energy
        self.results["forces"] = f_pc
        if periodic and self.domain is None and abs(atoms.cell.volume) > 0:
            p = [float(thermo[f"c_fanvir[{k}]"]) for k in range(1, 7)]
            p_cc = np.array([[p[0], p[3], p[4]], [p[3], p[1], p[5]], [p[4], p[5], p[2]]])
            ase_volume = abs(atoms.cell.volume)
            s_cc = -box.tensor_to_ase(p_cc) * box.lammps_volume / ase_volume
            diag = -volume
            if self.dx is None:  # v0 = vt = V/N: E + V scales with V^2
                diag += 2.0 * (energy + volume)
            for a in range(self.dim):
                s_cc[a, a] += diag / ase_volume
            self.results["stress"] = s_cc.flat[[0, 4, 8, 5, 2, 1]]


def fan_calculator(h, dx=None, dim=2, style="lepton", **kwargs):
    """An ASE calculator for Fan's total error evaluated in LAMMPS.

    See :class:`FanLammpsCalculator` for the parameters.
    """
    return FanLammpsCalculator(h, dx=dx, dim=dim, style=style, **kwargs)
