"""run a start at rest downstream (BISPH or LAMMPS) and say how calm it stays

Takes a particle file (the packed.extxyz of ``sphrelax pack``, the output of ``relax`` or ``density``, or
your own extxyz; a ``type`` column 1 fluid / 2 wall, without it every particle is fluid) and the tank it
was made for (--boundary, an edge file: the water region, its top edge the free surface), and runs it
at rest under gravity (periodic input, from ``pack --periodic``: without gravity, --solver bisph, --c0
required) for --t-end seconds of physical time:

* --solver bisph: boundary-integral walls (BIPI Eqs. 16-21, ``ase_sphrelax.flows.BISPH``; mu = 10 Pa s,
  c0 = 10 sqrt(2 g H)); wall particles in the file are ignored;
* --solver lammps: wall particles (``lammps_io.hydrostatic_tank``: the file's type-2 particles, from
  ``pack --walls`` (grid) or ``--walls --wall-mode packed``), Monaghan alpha 0.5, c0 = 10 sqrt(g H).

--compare cartesian also runs the Cartesian start of the same water region (BIPI's Step 1 at the same
dx, below the same surface, with the same wall particles) and prints which start is calmer and by how
much: compare.ke_ratio in summary.json is the run-averaged KE of IN over the Cartesian start's.

Writes to --out: summary.json (ke_history as [t, KE] in J/m, ke_mean, ke_final, pressure_error (RMS
deviation from rho0 g (surface - y), over rho0 g H, at the end), max_drop (largest downward
displacement, in dx), n_fluid, the parameters, compare) and settle.png (KE(t), log scale).
Bad input (no fluid particle, no walls for lammps, dx not the particles' spacing, h and dx swapped, a
tank in mm, 3D particles) is refused in one line (exit 2) before any run. Python:
``ase_sphrelax.settle(atoms, boundary, dx, solver="bisph", t_end=...)``.
"""
from __future__ import annotations

import json
import sys
import time
from pathlib import Path

from .common import add_output_arguments, add_progress_argument, output_folder, provenance, show_progress
from .usage import UsageError, positive, usage_errors

__all__ = ["add_arguments", "run", "plot_settle"]

COMMAND = "settle"


def add_arguments(parser):
    parser.add_argument("input", metavar="IN", help="particle file (extxyz, e.g. packed.extxyz of sphrelax pack)")
    parser.add_argument("--boundary", required=True,
                        help="the tank: an edge file ('x1 y1 x2 y2' per line), the water region the start was "
                             "packed in (its top edge is the free surface)")
    parser.add_argument("--dx", type=positive(float), required=True, help="particle spacing (masses rho0 dx^2)")
    parser.add_argument("--solver", choices=("bisph", "lammps"), default="bisph",
                        help="bisph: boundary-integral walls (BIPI Eqs. 16-21, no wall particles needed); lammps: "
                             "wall particles of the file (type 2) in lammps_io.hydrostatic_tank (default bisph)")
    parser.add_argument("--t-end", type=positive(float), required=True, help="physical time of the run (s)")
    parser.add_argument("--h", type=positive(float), default=4.0,
                        help="kernel support radius in units of dx (default 4: the paper's h_B = 2 dx); 1.5-6")
    parser.add_argument("--compare", choices=("cartesian",), default=None,
                        help="also run the Cartesian start (BIPI's Step 1) of the same water region and compare")
    parser.add_argument("--c0", type=positive(float), default=None,
                        help="speed of sound (m/s; default 10 sqrt(2 g H) for bisph, 10 sqrt(g H) for lammps; "
                             "required for periodic input)")
    parser.add_argument("--g", type=positive(float), default=9.81, help="gravity (m/s^2, default 9.81)")
    parser.add_argument("--alpha", type=float, default=0.5, help="lammps: Monaghan's artificial viscosity (0.5)")
    parser.add_argument("--p-background", type=float, default=None,
                        help="bisph, periodic input only: background pressure P_B (Pa; default rho0 (c0/10)^2)")
    parser.add_argument("--samples", type=positive(int), default=200, help="KE samples over the run (200)")
    add_output_arguments(parser, "sphrelax_settle", "summary.json, settle.png")
    add_progress_argument(parser)


def plot_settle(record, path, title=""):
    """KE(t) on a log scale, the input and (``compare``) the Cartesian start; a 256-colour PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    from PIL import Image

    fig, ax = plt.subplots(figsize=(5.5, 3.5))
    curves = [("input", record["ke_history"])]
    if "compare" in record:
        curves.append(("cartesian", record["compare"]["ke_history"]))
    for label, ke in curves:
        t, k = np.asarray(ke, dtype=float).T
        ax.semilogy(t[k > 0], k[k > 0], label=label)  # KE(0) = 0 at rest: not on a log axis
    ax.set_xlabel("t (s)")
    ax.set_ylabel("KE (J/m)")
    ax.set_title(title, fontsize=9)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    with Image.open(path) as image:
        image.convert("RGB").quantize(colors=256).save(path, optimize=True)
    return path


def run(args):
    t_start = time.perf_counter()
    with usage_errors():
        out = output_folder(args)
        for name in ("input", "boundary"):
            if not Path(getattr(args, name)).is_file():
                raise UsageError(f"{'IN' if name == 'input' else '--' + name} {getattr(args, name)!r}: no such file")
        from ase.io import read

        from ..boundary import as_boundary
        from ..flows.settle import check_settle, settle

        atoms = read(args.input)
        boundary = as_boundary(Path(args.boundary))
        kwargs = dict(solver=args.solver, t_end=args.t_end, h=args.h * args.dx, compare=args.compare, c0=args.c0,
                      g=args.g, alpha=args.alpha, p_background=args.p_background, samples=args.samples,
                      progress=show_progress(args))
        try:
            check_settle(atoms, boundary, args.dx, **kwargs)
        except ImportError as error:
            raise UsageError(f"--solver lammps: {' '.join(str(error).split())}") from None
    record = settle(atoms, boundary, args.dx, **kwargs)
    record.update(input=str(args.input), boundary=str(args.boundary), wall_time_s=time.perf_counter() - t_start)
    out.mkdir(parents=True, exist_ok=True)
    (out / "summary.json").write_text(json.dumps(dict(record, **provenance(args, COMMAND)), indent=1) + "\n")
    plot_settle(record, out / "settle.png", title=f"{Path(args.input).name}: {args.solver}, dx = {args.dx:g}")
    print(f"{Path(args.input).name}: {record['n_fluid']} fluid particles, {args.solver} ({record['wall_model']}), "
          f"{record['steps']} steps to t = {args.t_end:g} s")
    error = "n/a" if record["pressure_error"] is None else f"{100 * record['pressure_error']:.3g} %"
    print(f"KE: mean {record['ke_mean']:.4g} J/m, final {record['ke_final']:.4g} J/m; pressure error {error}; "
          f"max drop {record['max_drop']:.3g} dx")
    if not record.get("stable", True):
        print(f"sphrelax settle: warning: unstable run: {record['stability_reason']}", file=sys.stderr)
    if "compare" in record:
        c = record["compare"]
        print(f"Cartesian start: {c['n_fluid']} fluid particles, KE mean {c['ke_mean']:.4g} J/m; ke_ratio "
              f"{c['ke_ratio']:.4g}: {c['verdict']}")
    print(f"wrote {out / 'summary.json'}, {out / 'settle.png'}")
    return 0
