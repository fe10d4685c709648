"""pack particles against a boundary given by its elements (BIPI: edge files, STL meshes)

Boregowda & Liu's boundary-integral packing (BIPI): Step 1 fills the boundary with one particle per
Cartesian cell centre, Step 2 moves them (2a near the boundary, 2b freezes the first layer, 2c all
unfrozen ones) until the 1 % stopping rules or the iteration caps. A progress bar per stage; prints
the final metrics and the wall time; writes packed.extxyz, packed.png (particles coloured by
the norm of grad C_a), history.png and summary.json (parameters, summary, the per-iteration history) to --out.

--h is the kernel support in units of dx, as for ``sphrelax relax`` (default 4: BIPI2D's
h_B / dx_r = 2); --h-paper gives the paper's h_B / dx_r instead (h = 2 h_B). Both values are printed.
The support must be more than 1 dx (refused otherwise) and below 1.5 dx gives a warning (--strict: an
error), as for ``sphrelax relax``.

--periodic x (x, y or "x y" in 2D; x, y, z in 3D) makes the boundary periodic along those axes: the
edges (or triangles) on the periodic faces, e.g. the ends of a channel drawn as a closed rectangle, are
dropped (a line says how many), gamma and the pair sums see the periodic images, and packed.extxyz carries
the periodic cell. The period is the boundary's extent along the axis, which must then be a whole number of
dx (a usage error otherwise), unless --cell gives it (one length per axis of the boundary; 0 takes the extent).

--walls adds wall particles outside the boundary (type 2; the fluid is type 1), none inside the fluid and none
within 0.5 dx of a fluid particle; --open-top or --surface Y leaves the free surface open (no lid).

Before the fill the particle count and memory are estimated and printed; past --max-particles
(default 2e7) the fill is refused.

Exit status: 0 when Steps 2a and 2c stopped by their 1 % rules, or when an iteration cap was given
(--max-steps-2a/2c: a fixed length; an unconverged run then warns); 3 when a default cap was reached
first, the mean norm of grad C ended worse than it started, or the run was degenerate (every particle frozen:
nothing to pack); summary.json says ``converged`` and why. 2 for a usage error (one line).
"""
from __future__ import annotations

import json
import math
import sys
import time
import warnings
from pathlib import Path

from . import registry
from .common import (EXIT_NOT_CONVERGED, add_output_arguments, add_progress_argument, add_size_argument,
                     check_fill_size, check_h_ratio, output_folder, provenance, show_progress)
from .usage import UsageError, non_negative_int, positive, unit_interval_open, usage_errors

__all__ = ["add_arguments", "run", "BIPIMethod", "parse_periodic", "parse_cell", "periodic_boundary"]

COMMAND = "pack"


class BIPIMethod:
    """Boregowda & Liu's BIPI packer (Eq. 14-15, Steps 2a-2c) with exact boundary integrals

    A pack method provides ``pack(boundary, dx, h, args) -> (atoms, packer, start)`` (the set-up,
    where its input checks become usage errors, happens in ``prepare(boundary, dx, h, args)``)
    and optionally ``add_arguments(parser)``.
    """

    @staticmethod
    def add_arguments(parser):
        # no package imports here: building the parser must stay light (sphrelax --help)
        parser.add_argument("--max-steps-2a", type=non_negative_int, default=None,
                            help="iteration cap of Step 2a (default BIPI2D's 5000)")
        parser.add_argument("--max-steps-2c", type=non_negative_int, default=None,
                            help="iteration cap of Step 2c (default BIPI2D's 1000)")
        parser.add_argument("--tol", type=positive(float), default=0.01,
                            help="stopping rule: relative change of TPD_avg (2a) and |grad C|_avg (2c) (0.01)")
        parser.add_argument("--window", type=positive(int), default=10,
                            help="stopping rule: the change is taken over this many iterations (10)")
        parser.add_argument("--band-rule", choices=("ball", "normal", "centroid"), default="ball",
                            help="which part of the boundary feels the step pressure within 0.5 dx: ball (the part "
                                 "within 0.5 dx, default), normal (Eq. 14 as written), centroid (Eq. 21 as written)")
        parser.add_argument("--outside", choices=("raise", "move"), default="raise",
                            help="particles starting outside: refuse (default) or move them 0.5 dx inside")
        parser.add_argument("--momentum", type=unit_interval_open, default=0.0, metavar="BETA",
                            help="heavy-ball momentum in Step 2c (0, the default, is the paper's Eq. 14-15; 0.9 "
                                 "halved the 3D sphere's time with the same boundary layer, reproductions/speed-bipi-sphere)")

    @staticmethod
    def prepare(boundary, dx, h, args):
        from ..calculators.bipi import BIPICalculator
        from ..drivers.bipi_packer import CAP_2A, CAP_2C, BIPIPacker, initial_fill

        calc = BIPICalculator(h=h, dx=dx, boundary=boundary, band_rule=args.band_rule)
        check_fill_size(boundary.domain, dx, args.max_particles, what="Step 1 fill")
        atoms = initial_fill(boundary, dx, max_particles=args.max_particles)
        start = atoms.copy()
        caps = (CAP_2A if args.max_steps_2a is None else args.max_steps_2a,
                CAP_2C if args.max_steps_2c is None else args.max_steps_2c)
        packer = BIPIPacker(atoms, calc, max_steps_2a=caps[0], max_steps_2c=caps[1],
                            tol=args.tol, window=args.window, outside=args.outside,
                            momentum=args.momentum, progress=show_progress(args))
        return atoms, packer, start

    @staticmethod
    def pack(atoms, packer):
        packer.run()
        return atoms, packer


def add_arguments(parser):
    methods = registry.methods(COMMAND)
    parser.add_argument("--method", choices=tuple(methods), default="bipi",
                        help="packing method (" + "; ".join(f"{n}: {registry.help_texts(o)[0]}"
                                                             for n, o in methods.items()) + "; default bipi)")
    parser.add_argument("--boundary", required=True,
                        help="the boundary: an edge file ('x1 y1 x2 y2' per line, closed loops with the inside on the "
                             "left, holes clockwise) or a closed mesh trimesh reads (.stl, .obj, .ply)")
    parser.add_argument("--dx", type=positive(float), required=True, help="particle spacing dx_r")
    size = parser.add_mutually_exclusive_group()
    size.add_argument("--h", type=positive(float), default=None,
                      help="kernel support radius in units of dx (default 4, i.e. the paper's h_B/dx_r = 2)")
    size.add_argument("--h-paper", type=positive(float), default=None,
                      help="the paper's smoothing length ratio h_B/dx_r instead (support h = 2 h_B)")
    add_output_arguments(parser, "sphrelax_pack", "packed.extxyz, packed.png, history.png, summary.json")
    add_progress_argument(parser)
    add_size_argument(parser)
    parser.add_argument("--walls", type=positive(int), nargs="?", const=0, default=None, metavar="K",
                        help="also write wall particles outside the boundary: K layers (default ceil(h/dx)) of the "
                             "Step-1 grid (the cell centres Step 1 dropped within dx/8 of the boundary moved to just "
                             "outside it) or packed (--wall-mode); none inside the fluid and none within 0.5 dx of a "
                             "fluid particle (those are left out); packed.extxyz then carries a 'type' column (1 fluid, "
                             "2 wall). Walls surround the whole boundary unless --open-top or --surface leaves the "
                             "free surface open")
    surface = parser.add_mutually_exclusive_group()
    surface.add_argument("--open-top", action="store_true",
                         help="with --walls: the top of the boundary (its largest y in 2D, z in 3D) is a free "
                              "surface: no wall particle at or above it (no lid)")
    surface.add_argument("--surface", type=float, default=None, metavar="Y",
                         help="with --walls: the free surface's height (y in 2D, z in 3D), at or above the top of the "
                              "fluid: no wall particle at or above it")
    parser.add_argument("--periodic", nargs="+", default=None, metavar="AXIS",
                        help="periodic axes: x, y or 'x y' in 2D; x, y, z in 3D (edges on the periodic faces are "
                             "dropped; the period is the boundary's extent, which must then be a whole number of "
                             "dx, unless --cell gives it)")
    parser.add_argument("--cell", nargs="+", default=None, metavar="L",
                        help="with --periodic: the cell lengths along x, y (and z in 3D), one per axis of the boundary; "
                             "0 takes the boundary's extent")
    parser.add_argument("--wall-mode", choices=("grid", "packed"), default=None,
                        help="with --walls: on the Step-1 grid (default) or BIPI-packed in the band, in layers along "
                             "the walls")
    parser.add_argument("--strict", action="store_true", help="set-up warnings (e.g. --h below 1.5) become errors")
    for name, obj in methods.items():
        if hasattr(obj, "add_arguments"):
            obj.add_arguments(parser.add_argument_group(f"--method {name}"))


def parse_periodic(values, dim):
    """``--periodic`` tokens (``["x", "y"]``, ``["x y"]``, ``["x,y"]``) as a pbc list of length 3."""
    accepted = "x, y, or x y in 2D" if dim == 2 else "x, y, z (any of them) in 3D"
    axes = [a for v in values for a in v.replace(",", " ").split()]
    pbc = [False, False, False]
    if not axes:
        raise UsageError(f"--periodic: no axis given; accepted: {accepted}")
    for a in axes:
        if a not in "xyz"[:dim] or len(a) != 1:
            raise UsageError(f"--periodic: {a!r} is not an axis of the {dim}D boundary; accepted: {accepted}")
        if pbc["xyz".index(a)]:
            raise UsageError(f"--periodic: axis {a} given twice; accepted: {accepted}")
        pbc["xyz".index(a)] = True
    return pbc


def parse_cell(values, dim):
    """``--cell`` lengths (one per axis of the boundary, >= 0)."""
    try:
        lengths = [float(v) for v in values]
    except ValueError:
        raise UsageError(f"--cell: {values!r} are not numbers; give {dim} lengths (x y{' z' if dim == 3 else ''}), "
                         "0 for the boundary's extent") from None
    if len(lengths) != dim or not all(math.isfinite(v) and v >= 0 for v in lengths):
        raise UsageError(f"--cell: give {dim} finite lengths >= 0 (x y{' z' if dim == 3 else ''}; 0 takes the "
                         f"boundary's extent), got {' '.join(values)}")
    return lengths


def periodic_boundary(boundary, periodic, cell, dx=None):
    """The boundary made periodic by ``--periodic``/``--cell`` (one printed line on dropped face elements).

    With ``dx``: a period taken from the boundary's extent (no ``--cell`` length along that axis) must be a
    whole number of ``dx`` (a usage error otherwise: the spacing across the seam would differ from dx).
    """
    if periodic is None:
        if cell is not None:
            raise UsageError("--cell needs --periodic (the axes it makes periodic)")
        return boundary
    from ..boundary.periodic import PeriodicFacesWarning

    pbc = parse_periodic(periodic, boundary.dim)
    lengths = None if cell is None else parse_cell(cell, boundary.dim)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", PeriodicFacesWarning)
        try:
            out = boundary.with_cell(pbc, lengths)
        except ValueError as err:
            raise UsageError(f"--periodic/--cell: {err}") from None
    for w in caught:
        if issubclass(w.category, PeriodicFacesWarning):
            print(f"sphrelax pack: {w.message}")
        else:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    if dx is not None:
        for i in out.periodic.axes:
            if lengths is not None and lengths[i] > 0:
                continue  # the user gave this period
            ratio = out.periodic.period_c[i] / dx
            if abs(ratio - round(ratio)) > 1e-6 * max(1.0, ratio):
                axis = "xyz"[i]
                raise UsageError(f"--periodic {axis}: the boundary's extent along {axis} is "
                                 f"{out.periodic.period_c[i]:.6g} = {ratio:.6g} dx, not a whole number of dx (the "
                                 "spacing across the periodic seam would differ from dx); give the period with --cell "
                                 f"or a dx that divides it (e.g. {out.periodic.period_c[i] / max(1, round(ratio)):.6g})")
    print(f"periodic in {out.periodic.label}: period {out.periodic.period_c[out.pbc].tolist()}")
    return out


def surface_height(args, boundary):
    """``--open-top``/``--surface``: the height at and above which no wall particle is built, or None."""
    if args.walls is None:
        for given, name in ((args.wall_mode is not None, "--wall-mode"), (args.open_top, "--open-top"),
                            (args.surface is not None, "--surface")):
            if given:
                raise UsageError(f"{name} needs --walls (it sets how the wall particles are built)")
        return None
    up = boundary.dim - 1
    top = float(boundary.domain.bounds[1][up])
    if args.open_top:
        return top
    if args.surface is None:
        return None
    if not math.isfinite(args.surface) or args.surface < top - 1e-9 * max(1.0, abs(top)):
        raise UsageError(f"--surface {args.surface:g}: the fluid reaches {'yz'[up - 1]} = {top:.6g}, above the free "
                         "surface (it would have no side walls there); give a height at or above it, or --open-top")
    return float(args.surface)


def run(args):
    t_start = time.perf_counter()
    with usage_errors():
        from ..boundary import as_boundary

        method = registry.methods(COMMAND)[args.method]
        out = output_folder(args)
        path = Path(args.boundary)
        if not path.is_file():
            raise UsageError(f"--boundary {args.boundary!r}: no such file")
        boundary = periodic_boundary(as_boundary(path), args.periodic, args.cell, dx=args.dx)
        surface = surface_height(args, boundary)
        if args.walls is not None and args.wall_mode == "packed" and boundary.dim != 2:
            raise UsageError(f"--wall-mode packed: needs a 2D boundary (edge file), got a {boundary.dim}D one")
        if args.walls is not None and args.wall_mode == "packed" and args.periodic:
            raise UsageError("--wall-mode packed: not with --periodic (use --wall-mode grid, which keeps one period "
                             "of walls)")
        ratio = args.h if args.h is not None else (2.0 * args.h_paper if args.h_paper is not None else 4.0)
        if args.h_paper is not None:
            label = f"--h-paper {args.h_paper:g} (= --h {ratio:g}, the support in units of dx)"
        else:
            label = f"--h {ratio:g} (= --h-paper {ratio / 2:g}, the paper's h_B/dx_r)"
        notes = check_h_ratio(ratio, label)
        for note in notes:
            if args.strict:
                raise UsageError(f"{note} (--strict makes this an error)")
            print(f"sphrelax pack: warning: {note}", file=sys.stderr)
        h = ratio * args.dx
        atoms, packer, start = method.prepare(boundary, args.dx, h, args)

    from ase.io import write

    from ..analysis.quality import quality_summary
    from ..analysis.bipi import pack_summary
    from ..plotting import plot_concentration_gradient, plot_packing_history
    from .relax import _print_quality

    model = packer.model
    images = "" if boundary.periodic is None else f" with their images, periodic in {boundary.periodic.label}"
    print(f"boundary: {path.name} ({boundary.dim}D, {len(boundary)} elements{images}), {len(atoms)} particles, "
          f"dx = {args.dx:g}, h = {ratio:g} dx (support; the paper's h_B/dx_r = {ratio / 2:g}), method = {args.method}")
    before = quality_summary(start, h, dx=args.dx, domain=boundary.domain, dim=boundary.dim)
    from ..checks import NotConvergedWarning

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NotConvergedWarning)  # said below, in one line, with the exit status
        atoms, packer = method.pack(atoms, packer)
    summary = pack_summary(atoms, packer)
    converged, reason = packer.verdict()
    fixed = args.max_steps_2a is not None or args.max_steps_2c is not None
    wall = time.perf_counter() - t_start

    out.mkdir(parents=True, exist_ok=True)
    atoms.info.update(dx=args.dx, h=h, h_over_dx_paper=model.h_over_dx_paper, method=args.method)
    export = atoms.copy()
    export.set_constraint()
    if args.walls is not None:
        from ..drivers.bipi_packer import add_walls
        from ..drivers.bipi_walls import add_packed_walls

        mode = args.wall_mode or "grid"
        up = boundary.dim - 1
        if mode == "packed":
            import shapely

            lo, hi = boundary.domain.bounds
            pad = float((hi - lo).max()) + 10.0 * (args.walls or 10) * args.dx
            clip = None if surface is None else shapely.box(lo[0] - pad, lo[1] - pad, hi[0] + pad, surface)
            export = add_packed_walls(export, boundary, args.dx, layers=args.walls or None, h=h, clip=clip)
        else:
            keep = None if surface is None else (lambda r: r[:, up] < surface)
            export = add_walls(export, boundary, args.dx, layers=args.walls or None, h=h, keep=keep)
        open_side = "" if surface is None else f", none at or above the free surface {'yz'[up - 1]} = {surface:g}"
        print(f"wall particles: {export.info['n_wall']} in {export.info['wall_layers']} layers, {mode} "
              f"(type 2; fluid type 1){open_side}; {export.info['n_wall_dropped']} left out within 0.5 dx of the "
              "fluid")
    write(out / "packed.extxyz", export, format="extxyz")
    plot_concentration_gradient(atoms, packer.calc, out / "packed.png",
                                title=f"{path.name}: dx = {args.dx:g}, h = {ratio:g} dx; 2a {summary['iterations_2a']}, "
                                      f"2c {summary['iterations_2c']} iterations")
    plot_packing_history(packer.history, out / "history.png", title=path.name)
    summary.update(boundary=str(path), method=args.method, h_over_dx=ratio, quality_before=before,
                   periodic=[bool(p) for p in atoms.pbc[:boundary.dim]], cell=atoms.cell.array.tolist(),
                   wall_time_s=wall, n_wall=int(export.info.get("n_wall", 0)),
                   wall_layers=export.info.get("wall_layers"),
                   wall_mode=(args.wall_mode or "grid") if args.walls is not None else None,
                   n_wall_dropped=int(export.info.get("n_wall_dropped", 0)), surface=surface)
    (out / "summary.json").write_text(json.dumps(dict(summary=summary, parameters=packer.todict(),
                                                      history=packer.history, converged=converged,
                                                      convergence_reason=reason, **provenance(args, COMMAND)),
                                                 indent=1))
    print(f"Step 2a: {summary['iterations_2a']} iterations, TPD_avg = {summary.get('tpd_avg_2a', float('nan')):.4g}; "
          f"Step 2b: {summary['n_frozen']} frozen; Step 2c: {summary['iterations_2c']} iterations")
    if packer.degenerate:
        print("|grad C|_avg (unfrozen): no unfrozen particle, nothing was packed")
    else:
        print(f"|grad C|_avg (unfrozen): {summary.get('gradc_avg_2c_first', float('nan')):.4g} -> "
              f"{summary['gradc_avg_final']:.4g} ({summary['gradc_drop_orders']:.2f} orders)")
    print(f"boundary layer mean distance {summary['boundary_layer_mean']:.3f} dx (min {summary['boundary_layer_min']:.3f}), "
          f"{summary['n_outside']} particles outside")
    _print_quality(before, summary["quality"])
    print(f"wall time: {wall:.1f} s")
    print(f"wrote {out / 'packed.extxyz'}, {out / 'packed.png'}, {out / 'history.png'}, {out / 'summary.json'}")
    if converged:
        print(f"converged: {reason}")
        return 0
    if fixed and not packer.degenerate:
        print(f"sphrelax pack: warning: not converged (the iteration caps were given: exit 0): {reason}",
              file=sys.stderr)
        return 0
    print(f"sphrelax pack: not converged: {reason} (exit {EXIT_NOT_CONVERGED})", file=sys.stderr)
    return EXIT_NOT_CONVERGED
