"""Command line: ``sphrelax relax | lattice | table | export``.

``sphrelax relax`` with no options runs Fan et al.'s Appendix A scene: a circle
centred (0.5, 0.5) of radius 0.2, dx = 1/256 (8224 particles at background-cell
centres with a small random shift), h = 2.6 dx, Eq. 2.4 updates with c = 0.01.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

BUILTIN_DOMAINS = ("circle", "box", "sphere", "periodic")


def _positive(kind):
    def parse(text):
        value = kind(text)
        if not np.isfinite(value) or value <= 0:
            raise argparse.ArgumentTypeError(f"must be a positive number, got {text!r}")
        return value

    return parse


def _non_negative_int(text):
    value = int(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be an integer >= 0, got {text!r}")
    return value


def build_parser():
    parser = argparse.ArgumentParser(prog="sphrelax", description="SPH particle relaxation (ase_sphrelax)")
    sub = parser.add_subparsers(dest="command", required=True)

    relax = sub.add_parser("relax", help="relax particles in a domain (default: Fan et al. Appendix A circle)")
    relax.add_argument("--domain", default="circle",
                       help="circle (Fan's, centre 0.5 0.5 radius 0.2), box ([0.3, 0.7]^dim), sphere (centre 0.5, "
                            "radius 0.2, 3D), periodic (unit cell, interior case), or a path to an edge file "
                            "('x1 y1 x2 y2' per line) or a closed .stl mesh")
    relax.add_argument("--dx", type=_positive(float), default=None,
                       help="background cell size (default 1/256 in 2D, 1/32 in 3D; for files: extent/128 or /32)")
    relax.add_argument("--h", type=_positive(float), default=2.6, help="kernel cut-off radius in units of dx (2.6)")
    relax.add_argument("--steps", type=_non_negative_int, default=2000, help="maximum number of steps (2000)")
    relax.add_argument("--fmax", type=float, default=0.0,
                       help="stop when max |F| < fmax, in units of the initial max |F| (default 0: run all steps)")
    relax.add_argument("--optimizer", choices=("fan", "fire", "bfgs", "lbfgs"), default="fan",
                       help="fan: Eq. 2.4 with step c*h (default); fire/bfgs/lbfgs: ASE optimisers")
    relax.add_argument("--c", type=_positive(float), default=None,
                       help="step scale: Eq. 2.4 coefficient for fan; first step c*h for fire/bfgs/lbfgs "
                            "(default 0.01 for fan and fire, 0.05 for bfgs and lbfgs)")
    relax.add_argument("--dim", type=int, choices=(2, 3), default=None, help="dimension (default from the domain)")
    relax.add_argument("--jitter", type=float, default=0.1, help="initial random shift, fraction of dx (0.1)")
    relax.add_argument("--seed", type=int, default=0, help="random seed for the initial shift (0)")
    relax.add_argument("--out", default="sphrelax_out", help="output folder (relaxed.extxyz, relaxed.png, summary.json)")
    try:
        from lammps_io.cli import add_engine_arguments
    except ImportError:  # pragma: no cover - lammps_io ships with the package
        pass
    else:
        add_engine_arguments(relax)

    lattice = sub.add_parser("lattice", help="predicted and relaxed lattice pattern for a given h/dx (Fan Sec. 5)")
    lattice.add_argument("--h", type=_positive(float), required=True, help="h/dx")
    lattice.add_argument("--dim", type=int, choices=(2, 3), default=2)
    lattice.add_argument("--seed", type=int, default=0)

    table = sub.add_parser("table", help="write Table 2 (characteristic volumes) as CSV and a plot")
    table.add_argument("--dim", type=int, choices=(2, 3), default=2)
    table.add_argument("--out", default=None, help="CSV path (default table2_<dim>d.csv; the PNG goes beside it)")

    export = sub.add_parser("export", help="convert particles to LAMMPS data, extxyz or VTK")
    from lammps_io.cli import add_export_arguments

    add_export_arguments(export)
    return parser


# -- relax ---------------------------------------------------------------------
def make_scene(domain_name, dim=None, dx=None, jitter=0.1, seed=0):
    """Domain (or None for the periodic interior), dx and initial Atoms of a scene."""
    from .build import fill, periodic_box
    from .domains import Box, Circle, Mesh, Polygon, Sphere

    if domain_name == "periodic":
        dim = dim or 2
        dx = dx or (1 / 256 if dim == 2 else 1 / 32)
        n = int(round(1.0 / dx))
        atoms = periodic_box(n, dx=dx, dim=dim, jitter=jitter, seed=seed)
        return None, dx, atoms
    if domain_name == "circle":
        domain = Circle((0.5, 0.5), 0.2)
    elif domain_name == "sphere":
        domain = Sphere((0.5, 0.5, 0.5), 0.2)
    elif domain_name == "box":
        d = dim or 2
        domain = Box((0.3,) * d, (0.7,) * d)
    else:
        path = Path(domain_name)
        if not path.is_file():
            raise ValueError(f"--domain must be one of {BUILTIN_DOMAINS} or an existing edge/.stl file, "
                             f"got {domain_name!r}")
        domain = Mesh(str(path)) if path.suffix.lower() == ".stl" else Polygon.from_edges(path)
    if dim is not None and dim != domain.dim:
        raise ValueError(f"--dim {dim} does not match the {domain.dim}D domain {domain_name!r}")
    if dx is None:
        if domain_name in BUILTIN_DOMAINS:
            dx = 1 / 256 if domain.dim == 2 else 1 / 32
        else:
            lo, hi = domain.bounds
            dx = float(np.max(hi - lo)) / (128 if domain.dim == 2 else 32)
    atoms = fill(domain, dx, jitter=jitter, seed=seed)
    return domain, dx, atoms


def _progress(opt, atoms, steps, label):
    from tqdm.auto import tqdm

    bar = tqdm(total=steps, desc=label, unit="step", disable=None, mininterval=0.5)

    def update():
        bar.update(1)
        if opt.nsteps % 25 == 0:
            bar.set_postfix(E=f"{atoms.get_potential_energy():.6e}")

    opt.attach(update, interval=1)
    return bar


def relax_command(args):
    from ase.io import write

    from .analysis.quality import Quality
    from .calculators import FanCalculator
    from .drivers import make_optimizer
    from .plotting import plot_particles

    t_start = time.perf_counter()
    domain, dx, atoms = make_scene(args.domain, args.dim, args.dx, args.jitter, args.seed)
    dim = domain.dim if domain is not None else (args.dim or 2)
    h = args.h * dx
    quality = Quality(h, dx=dx, domain=domain, dim=dim)
    before = quality.compute(atoms).summary()
    print(f"scene: {args.domain} ({dim}D), {len(atoms)} particles, dx = {dx:.6g}, h = {args.h:g} dx, "
          f"optimizer = {args.optimizer if getattr(args, 'engine', 'ase') == 'ase' else 'lammps fire'}")
    atoms.calc = FanCalculator(h=h, dx=dx, domain=domain, dim=dim)
    e_before = atoms.get_potential_energy()
    if getattr(args, "engine", "ase") == "lammps":
        from lammps_io.cli import cli_relax

        atoms = cli_relax(atoms, h, dx=dx, domain=domain, steps=args.steps, nprocs=args.nprocs,
                          nthreads=args.nthreads, style=args.lammps_style)
        steps_done = args.steps
        stop_reason = "LAMMPS minimisation finished"
        atoms.calc = FanCalculator(h=h, dx=dx, domain=domain, dim=dim)
    else:
        f0 = float(np.linalg.norm(atoms.get_forces(), axis=1).max())
        opt = make_optimizer(args.optimizer, atoms, c=args.c)
        bar = _progress(opt, atoms, args.steps, f"relax ({args.optimizer})")
        try:
            converged = opt.run(fmax=args.fmax * f0, steps=args.steps)
        finally:
            bar.close()
        steps_done = opt.nsteps
        stop_reason = (f"converged: max |F| < {args.fmax:g} x initial" if converged
                       else f"reached --steps {args.steps}")
    e_after = atoms.get_potential_energy()
    after = quality.compute(atoms).summary()
    wall = time.perf_counter() - t_start

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    atoms.new_array("volume", quality.volume_p)
    if quality.phi_p is not None:
        atoms.new_array("phi", quality.phi_p)
    atoms.info.update(dx=dx, h=h, steps=steps_done)
    write(out / "relaxed.extxyz", atoms, format="extxyz")
    plot_particles(atoms, quality.volume_p / dx**dim, out / "relaxed.png", domain=domain, dx=dx,
                   title=f"{args.domain}: h = {args.h:g} dx, {steps_done} steps ({args.optimizer})",
                   label="particle volume 1/Σ_j W_ij  [dx^d]", range_mask=quality.interior_p)
    summary = dict(scene=args.domain, dim=dim, n_particles=len(atoms), dx=dx, h_over_dx=args.h,
                   optimizer=args.optimizer, steps=steps_done, stop_reason=stop_reason,
                   energy_before=e_before, energy_after=e_after, quality_before=before, quality_after=after,
                   wall_time_s=wall)
    (out / "summary.json").write_text(json.dumps(summary, indent=2))

    print(f"stopped after {steps_done} steps: {stop_reason}")
    print(f"total error E (Eq. 3.8): {e_before:.6e} -> {e_after:.6e}")
    _print_quality(before, after)
    print(f"wall time: {wall:.1f} s")
    print(f"wrote {out / 'relaxed.extxyz'}, {out / 'relaxed.png'}, {out / 'summary.json'}")
    return 0


def _print_quality(before, after):
    rows = [("mean |Σ V W - 1| (interior)", "kernel_sum_error_mean"),
            ("max  |Σ V W - 1| (interior)", "kernel_sum_error_max"),
            ("mean h|Σ V ∇W|  (interior)", "gradient_error_mean"),
            ("max  h|Σ V ∇W|  (interior)", "gradient_error_max"),
            ("boundary layer -φ/dp mean", "boundary_distance_mean"),
            ("boundary layer -φ/dp min", "boundary_distance_min"),
            ("max φ/dp (escape if > 0)", "max_phi_over_dp"),
            ("particles outside (φ > 0)", "n_outside")]
    print(f"{'metric':32s} {'initial':>12s} {'relaxed':>12s}")
    for label, key in rows:
        if key in after:
            print(f"{label:32s} {before[key]:12.4g} {after[key]:12.4g}")


def lattice_command(args):
    from .analysis.patterns import lattice_report

    print(lattice_report(args.h, dim=args.dim, seed=args.seed))
    return 0


def table_command(args):
    from .analysis.patterns import write_table

    csv = Path(args.out or f"table2_{args.dim}d.csv")
    png = csv.with_suffix(".png")
    write_table(csv, png, dim=args.dim)
    print(f"wrote {csv} and {png}")
    return 0


def export_command(args):
    from lammps_io.cli import cli_export

    path = cli_export(args.input, args.output, fmt=args.format, atom_style=args.atom_style, units=args.units,
                      dx=args.dx, rho0=args.rho0, margin=args.margin)
    print(f"wrote {path}")
    return 0


COMMANDS = {"relax": relax_command, "lattice": lattice_command, "table": table_command, "export": export_command}


def main(argv=None):
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return COMMANDS[args.command](args)
    except (ValueError, TypeError, FileNotFoundError, ImportError) as error:
        print(f"sphrelax {args.command}: error: {error}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
