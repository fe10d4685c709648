"""ASE calculator evaluating Fan's total error (Eq. 3.8) with LAMMPS.

The model (volumes, self term, boundary term, stress correction) is
:class:`ase_sphrelax.models.fan.FanModel`, the one :class:`~ase_sphrelax.FanCalculator`
uses: both backends accept the same parameters and raise the same errors. The pair part
runs in LAMMPS (``pair_style lepton`` or ``table``, see :mod:`lammps_io.potential`); the
constant self term ``N v0 vt W(0) - V`` and, for a bounded ``domain``, the level-set
boundary term (Eq. 3.8 last term, force Eq. 4.4) are added in numpy.
"""
from __future__ import annotations

import ctypes
import tempfile
from pathlib import Path

import numpy as np

from ase_sphrelax.calculators.base import SPHCalculator, periodic_measure
from ase_sphrelax.models.fan import FanModel, verlet_skin

from ._library import check_threads, import_lammps, new_lammps
from .box import lammps_box
from .potential import check_pair_style, check_table_points, pair_commands

__all__ = ["FanLammpsCalculator", "fan_calculator"]


def _gather(lmp, name, n):
    """Per-atom 3-vector ordered by atom id, as an (n, 3) array (no Python float lists)."""
    data = lmp.gather_atoms(name, 1, 3)
    return np.frombuffer(data, dtype=np.float64, count=3 * n).reshape(n, 3).copy()


class FanLammpsCalculator(SPHCalculator):
    """Fan's total error E (Eq. 3.8), forces (Eq. 3.17/4.4) and stress from LAMMPS.

    Parameters are kept in ``self.parameters`` (ASE convention) and validated like
    :class:`~ase_sphrelax.FanCalculator`'s; ``set()`` with a change discards the results
    and the LAMMPS instance, which the next evaluation rebuilds.

    Parameters
    ----------
    h : float
        Kernel support radius.
    dx : float or None
        Particle spacing: v0 = vt = dx^dim. None: v0 = vt = V/N, V the domain volume
        or the periodic cell measure (:meth:`ase_sphrelax.models.fan.FanModel.volumes`).
    dim : {1, 2, 3} or None
        None (default): the domain's, else inferred from the atoms by
        :func:`ase_sphrelax.checks.resolve_dim`, as :class:`~ase_sphrelax.FanCalculator`.
    style : {"lepton", "table"}
        Exact expression or a spline table of ``n_table`` points (piecewise kernels need ``"table"``).
    domain : Domain or None
        Bounded domain with ``phi_and_normal`` and ``volume``; adds the boundary term.
    kernel : str
        Kernel name (:data:`ase_sphrelax.kernels.KERNEL_NAMES`).
    n_table : int
        Points of the ``table`` style (>= 2).
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
    default_parameters = dict(h=None, dx=None, domain=None, dim=None, kernel="wendland_c2", skin=None,
                              style="lepton", n_table=20000, nthreads=1, reuse_neighbors=False)

    def __init__(self, h=None, dx=None, dim=None, style="lepton", domain=None, kernel="wendland_c2", n_table=20000,
                 nthreads=1, skin=None, reuse_neighbors=False, **kwargs):
        self._lmp = None
        self._key = None
        self._tmp = None
        super().__init__(h=h, dx=dx, domain=domain, dim=dim, kernel=kernel, skin=skin, style=style,
                         n_table=n_table, nthreads=nthreads, reuse_neighbors=reuse_neighbors, **kwargs)
        import_lammps()  # fail early with the install hint

    def _validate_parameters(self):
        super()._validate_parameters()
        p = self.parameters
        self.model = FanModel.from_parameters(p)
        self.skin = verlet_skin(p.skin, self.model.h)  # None: 0.1 h of the current h
        check_pair_style(p.style, self.model.kernel, self.model.dim)
        p.n_table = check_table_points(p.n_table)
        p.nthreads = check_threads(p.nthreads)
        if not isinstance(p.reuse_neighbors, (bool, np.bool_)):
            raise ValueError(f"reuse_neighbors must be True or False, got {p.reuse_neighbors!r}")
        p.reuse_neighbors = bool(p.reuse_neighbors)

    def set(self, **kwargs):
        """Change parameters; any change discards the results and the LAMMPS instance."""
        changed = super().set(**kwargs)
        if changed:
            self.close()
        return changed

    # -- LAMMPS instance -------------------------------------------------------
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

    def _build(self, box, v0):
        self.close()
        p = self.parameters
        model = self.model
        lmp = new_lammps(nthreads=p.nthreads)
        if self._tmp is None:
            self._tmp = tempfile.TemporaryDirectory(prefix="lammps_io_")
        boundary = " ".join("p" if periodic else "m" for periodic in box.pbc)
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
        n = len(box.r_pc)
        lmp.create_atoms(n, list(range(1, n + 1)), [1] * n, box.r_pc.ravel().tolist())
        cmds = pair_commands(model.h, model.dx, model.dim, style=p.style, kernel=model.kernel,
                             table_path=Path(self._tmp.name) / "fan.table", n_table=p.n_table, v0=v0)
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

    def _run(self, box, n, rebuilt, periodic):
        """Move the atoms to ``box.r_pc`` and evaluate: ``run 0`` (full set-up) or, reusing
        neighbours, one ``fix nve/noforce`` step."""
        lmp = self._lmp
        if rebuilt or not self.parameters.reuse_neighbors:
            if not rebuilt:
                x = np.ascontiguousarray(box.r_pc.ravel())
                lmp.scatter_atoms("x", 1, 3, (ctypes.c_double * (3 * n)).from_buffer(x))
                # a new timestep: thermo serves computes (pe, the virial) cached per timestep, so a second
                # `run 0` at the same step reported the previous positions' energy and stress (forces were new)
                lmp.command(f"reset_timestep {lmp.extract_global('ntimestep') + 1}")
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
                act = slice(0, box.dim)
                frac = np.linalg.solve(cell_lmp[act, act].T, d_pc[:, act].T).T
                d_pc[:, act] = (frac - np.round(frac)) @ cell_lmp[act, act]
            v = np.ascontiguousarray(d_pc.ravel())
            lmp.scatter_atoms("v", 1, 3, (ctypes.c_double * (3 * n)).from_buffer(v))
            lmp.command("run 1 pre no post no")

    # -- the calculator contract (ase_sphrelax.calculators.base) -----------------
    def configure(self, dim):
        self.model = self.model.with_dim(dim)
        check_pair_style(self.parameters.style, self.model.kernel, dim)

    def check_atoms(self, atoms, dim, properties):
        if "stress" in properties:
            vols = self.model.volumes(len(atoms), periodic_measure(atoms.cell.array, atoms.pbc, dim))
            self.model.check_stress(vols, atoms.cell.volume)

    def cutoff(self, atoms, dim):
        return None  # LAMMPS keeps its own neighbour list

    def evaluate(self, state, properties):
        atoms, model = state.atoms, self.model
        n = len(atoms)
        vols = model.volumes(n, periodic_measure(atoms.cell.array, atoms.pbc, model.dim))
        periodic = vols.measure is not None
        box = lammps_box(atoms, dim=model.dim, margin=model.h)
        key = (model.dim, n, tuple(atoms.pbc), atoms.cell[:].tobytes(), vols.v0, box.lo_c.tobytes() if periodic else None)
        rebuilt = False
        if self._lmp is None or key != self._key:
            self._build(box, vols.v0)
            self._key = key
            rebuilt = True
        try:
            self._run(box, n, rebuilt, periodic)
        except Exception:
            self.close()  # never reuse an instance LAMMPS stopped in
            raise
        lmp = self._lmp
        thermo = lmp.last_thermo()
        f_pc = box.to_ase(_gather(lmp, "f", n))
        if not np.all(np.isfinite(f_pc)):
            bad = np.where(~np.all(np.isfinite(f_pc), axis=1))[0]
            raise ValueError(f"atoms: LAMMPS gave non-finite forces on particles {bad[:10].tolist()}: coincident "
                             "particles (r = 0) make pair_style lepton divide by r; separate them or use FanCalculator")
        energy = float(thermo["PotEng"]) + model.self_energy(n, vols.v0, vols.volume)
        if model.domain is not None:
            boundary_e_p, boundary_f_pc = model.boundary(atoms.positions, vols.v0)
            energy += float(boundary_e_p.sum())
            f_pc += boundary_f_pc
        out = dict(energy=energy, forces=f_pc)
        if "stress" in properties:
            v = [float(thermo[f"c_fanvir[{k}]"]) for k in range(1, 7)]
            pressure_cc = np.array([[v[0], v[3], v[4]], [v[3], v[1], v[5]], [v[4], v[5], v[2]]])
            # LAMMPS' virial pressure is -(1/V) dE/d(strain)
            pair_virial_cc = -box.tensor_to_ase(pressure_cc) * box.lammps_volume
            out["stress"] = model.stress(pair_virial_cc, energy, vols, atoms.cell.volume)
        return out


def fan_calculator(h=None, dx=None, dim=None, style="lepton", **kwargs):
    """An ASE calculator for Fan's total error evaluated in LAMMPS.

    See :class:`FanLammpsCalculator` for the parameters.
    """
    return FanLammpsCalculator(h, dx=dx, dim=dim, style=style, **kwargs)
