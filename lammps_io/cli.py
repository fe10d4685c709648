"""``sphrelax export`` and ``sphrelax relax --engine lammps``, registered by entry point.

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
from ase_sphrelax.cli.usage import UsageError, positive, usage_errors

from .box import infer_dim
from .data_file import ATOM_STYLES, UNIT_STYLES, write_data

MIN_STYLES = ("fire", "cg", "sd", "quickmin")  # the LAMMPS min_style values the relaxation deck accepts

__all__ = ["EXPORT_FORMATS", "ENGINES", "ExportCommand", "LammpsEngine", "add_export_arguments",
           "add_engine_arguments", "cli_export", "cli_relax", "write_vtk", "export_format_from_path"]

EXPORT_FORMATS = ("lammps", "extxyz", "vtk")
# the engines of ``add_engine_arguments`` (a parser of your own); sphrelax lists its engines from the registry
ENGINES = ("ase", "lammps")
_SUFFIX_FORMAT = {".data": "lammps", ".lmp": "lammps", ".lammps": "lammps", ".xyz": "extxyz", ".extxyz": "extxyz",
                  ".vtk": "vtk"}


def export_format_from_path(path):
    """Format implied by the file suffix (.data/.lmp -> lammps, .xyz/.extxyz -> extxyz, .vtk -> vtk)."""
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
    parser.add_argument("--units", choices=UNIT_STYLES, default="lj",
                        help="LAMMPS unit system named in the data file (default lj; coordinates are not converted)")
    parser.add_argument("--dx", type=positive(float), default=None,
                        help="particle spacing (default atoms.info['dx'], else cell measure / N)")
    parser.add_argument("--rho0", type=positive(float), default=1.0, help="SPH density; mass = rho0 dx^dim (default 1)")
    parser.add_argument("--margin", type=float, default=None,
                        help="box margin around open (non-periodic) sets (default: dx)")
    return parser


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
    """Legacy ASCII VTK polydata: points, one vertex per particle, point arrays
    (velocities, forces, per-particle arrays of ``atoms.arrays`` with 1 or 3 components)."""
    dim = infer_dim(atoms) if dim is None else dim
    n = len(atoms)
    lines = ["# vtk DataFile Version 3.0", f"ase_sphrelax particles (dim {dim})", "ASCII", "DATASET POLYDATA",
             f"POINTS {n} double"]
    lines += [f"{x:.17g} {y:.17g} {z:.17g}" for x, y, z in atoms.positions]
    lines += [f"VERTICES {n} {2 * n}"] + [f"1 {i}" for i in range(n)]
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


def cli_export(atoms_or_path, output, fmt=None, atom_style="sph", units="lj", dx=None, rho0=1.0, margin=None,
               dim=None):
    """``sphrelax export``: write particles as a LAMMPS data file, extxyz or VTK.

    Parameters
    ----------
    atoms_or_path : ase.Atoms or path readable by ase.io.read
    output : str or Path
    fmt : {"lammps", "extxyz", "vtk", None}
        None: from the output suffix.
    atom_style, units :
        LAMMPS data file options (:func:`lammps_io.write_data`).
    dx : float or None
        Spacing for the particle volume dx^dim (mass = rho0 dx^dim, rho = rho0). With None and
        atom style sph, particles with a per-particle ``rho`` array and masses (``sphrelax density``)
        keep their own mass and density.
    rho0 : float
    margin : float or None
        Box margin for open sets (default dx).

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
    dim = infer_dim(atoms) if dim is None else dim
    if fmt == "vtk":
        return write_vtk(atoms, output, dim)
    spacing = _spacing(atoms, dim, dx)
    periodic = all(atoms.pbc[:dim])
    if margin is None and not periodic:
        margin = spacing
    volume = spacing**dim
    if atom_style == "sph" and dx is None and "rho" in atoms.arrays and atoms.has("masses"):
        # particles that carry their own SPH state (e.g. sphrelax density): keep each mass and density
        write_data(atoms, output, atom_style=atom_style, units=units, dim=dim, masses=atoms.get_masses(),
                   rho=atoms.arrays["rho"], margin=margin)
        return output
    write_data(atoms, output, atom_style=atom_style, units=units, dim=dim, masses=rho0 * volume, volume=volume,
               rho=rho0 if atom_style == "sph" else None, margin=margin)
    return output


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
    """convert particles to LAMMPS data, extxyz or VTK

    Reads any file ase.io.read understands (e.g. relaxed.extxyz of sphrelax relax).
    LAMMPS data files get mass = rho0 dx^dim and, for atom style sph, rho = rho0;
    open (non-periodic) sets get a box margin of dx.
    """

    add_arguments = staticmethod(add_export_arguments)

    @staticmethod
    def run(args):
        with usage_errors():
            fmt = args.format or export_format_from_path(args.output)
            atoms = _read(args.input)
            if fmt == "lammps":
                _spacing(atoms, infer_dim(atoms), args.dx)
        path = cli_export(atoms, args.output, fmt=fmt, atom_style=args.atom_style, units=args.units, dx=args.dx,
                          rho0=args.rho0, margin=args.margin)
        print(f"wrote {path}")
        return 0


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
