"""relax particles in a domain (default: Fan et al. Appendix A circle)

With no options this runs Fan et al.'s Appendix A scene: a circle centred
(0.5, 0.5) of radius 0.2, dx = 1/256 (8224 particles at background-cell centres
with a small random shift), h = 2.6 dx, Eq. 2.4 updates with c = 0.01.
Writes relaxed.extxyz, relaxed.png and summary.json to --out.

--method picks the model (the calculator whose energy is relaxed), --engine
what minimises it; both come from registries (ase_sphrelax.cli.registry).
Options listed under "--engine NAME" or "--method NAME" apply to that one only:
giving one with another engine or method is an error.

Lengths: --dx is a length, --h-over-dx (alias --h) is h in units of dx; in Python
FanCalculator(h=...) is a length. --fmax is an absolute force, as ASE's
Optimizer.run(fmax=...); --fmax-rel is relative to the initial largest force.

Particle volume: --particle-volume dx gives every particle v0 = dx^dim (Fan
Eq. 3.3, the default); V/N gives v0 = domain volume / N (Eq. 3.2), which makes
N v0 equal the domain volume exactly: use V/N for an SPH run (masses
rho0 V/N conserve the total mass). A relaxed interior has mean sum_j V_j W_ij
at the lattice optimum 1/v_c (Fan Sec. 5), about 1.009 at h = 2.6 dx, not 1;
the summary prints both.

Exit status: 0; 2 for a usage error (one line, before any work); with --strict,
set-up warnings are usage errors and a run that ends with particles outside
the domain exits with 1. Such a run says so on its last line in any case.
"""
from __future__ import annotations

import json
import sys
import time

from ..drivers.optimizers import DEFAULT_C, OPTIMIZERS
from . import STARTED, registry
from .common import (EXIT_NOT_CONVERGED, H_MIN, H_TABLE, add_output_arguments, add_progress_argument,
                     add_size_argument, output_folder, provenance, show_progress)
from .scene import DOMAIN_HELP, make_scene
from .usage import UsageError, non_negative_float, non_negative_int, positive, usage_errors

__all__ = ["add_arguments", "run", "FanMethod", "AseEngine", "particle_dx", "absolute_fmax", "H_MIN", "H_TABLE",
           "C_WARN", "VOLUME_TOL"]

COMMAND = "relax"
DEFAULT_STEPS = 2000
C_WARN = 0.1  # steps of more than 0.1 h: Eq. 2.4's error floor grows with c (Fan uses 0.01)
VOLUME_TOL = 0.01  # |N dx^d / V - 1| beyond this: the density is biased, say so
PARTICLE_VOLUMES = ("dx", "V/N")


def particle_dx(scene, args):
    """The ``dx`` of the Fan model for ``--particle-volume``: ``scene.dx`` (v0 = dx^d) or None (v0 = V/N)."""
    return None if getattr(args, "particle_volume", "dx") == "V/N" else scene.dx


def absolute_fmax(args, f0):
    """``--fmax`` (absolute), or ``--fmax-rel`` times the initial largest force ``f0``, or 0 (run all steps)."""
    if getattr(args, "fmax", None) is not None:
        return float(args.fmax)
    if getattr(args, "fmax_rel", None) is not None:
        return float(args.fmax_rel) * f0
    return 0.0


def _fmax_text(args):
    if getattr(args, "fmax", None) is not None:
        return f"max |F| < --fmax {args.fmax:g}"
    return f"max |F| < --fmax-rel {args.fmax_rel:g} x initial max |F|"


# -- methods and engines ------------------------------------------------------------------
class FanMethod:
    """Fan et al.'s total error E (Eq. 3.8) with its exact forces (FanCalculator)

    A relax method provides ``calculator(scene, h, args)`` (constructed in the
    set-up phase, so its input checks become usage errors) and optionally
    ``add_arguments(parser)`` and ``energy_label``.
    """

    energy_label = "total error E (Eq. 3.8)"

    @staticmethod
    def calculator(scene, h, args):
        from ..calculators import FanCalculator

        return FanCalculator(h=h, dx=particle_dx(scene, args), domain=scene.domain, dim=scene.dim)


class AseEngine:
    """the method's calculator with an optimiser in Python (Eq. 2.4 or an ASE optimiser)

    A relax engine provides ``relax(atoms, scene, h, args) -> (atoms, steps, stop_reason)``
    (``steps``: the iterations really done) and ``describe(args)`` (the driver's name for the
    log), and optionally ``add_arguments(parser)`` (options that apply to this engine only),
    ``methods`` (the method names it supports; None: all), ``optimizers`` (the ``--optimizer``
    names it accepts) with ``default_optimizer``, and ``check(args)`` (set-up phase: raise
    UsageError or ValueError; may return warnings as strings). Engines honour ``--steps``,
    ``--fmax`` and ``--fmax-rel`` (:func:`absolute_fmax`).
    """

    methods = None
    optimizers = OPTIMIZERS
    default_optimizer = "fan"

    @staticmethod
    def add_arguments(parser):
        defaults = ", ".join(f"{c:g} for {name}" for name, c in DEFAULT_C.items())
        parser.add_argument("--c", type=positive(float), default=None,
                            help="step scale, 0 < c < 1: Eq. 2.4 coefficient for fan (step c*h); first step c*h and "
                                 f"largest step 10 c*h for the ASE optimisers (default {defaults})")

    @staticmethod
    def check(args):
        from ..drivers.optimizers import check_c

        if args.c is None:
            return []
        check_c(args.c, name="--c")
        if args.c > C_WARN:
            return [f"--c {args.c:g}: steps of {args.c:g} h (Fan uses 0.01); the error where Eq. 2.4 stalls grows "
                    "with c and particles may be pushed against the boundary"]
        return []

    @staticmethod
    def describe(args):
        return args.optimizer

    @staticmethod
    def relax(atoms, scene, h, args):
        import numpy as np

        from ..drivers.optimizers import make_optimizer

        f0 = float(np.linalg.norm(atoms.get_forces(), axis=1).max())
        opt = make_optimizer(args.optimizer, atoms, c=args.c)  # keeps particles inside a domain (KeepInDomain)
        fmax = absolute_fmax(args, f0)
        bar = _progress(opt, atoms, args.steps, f"relax ({args.optimizer})", disable=not show_progress(args))
        try:
            converged = opt.run(fmax=fmax, steps=args.steps)
        finally:
            bar.close()
        cap = (f"reached --steps {args.steps}" if getattr(args, "steps_given", True)
               else f"reached the default step cap {args.steps} (no --steps given)")
        stop_reason = f"converged: {_fmax_text(args)}" if converged and fmax > 0 else cap
        return atoms, opt.nsteps, stop_reason


def _choices_help(objects):
    return "; ".join(f"{name}: {registry.help_texts(obj)[0]}" for name, obj in objects.items())


# -- the command ---------------------------------------------------------------------------
def add_arguments(parser):
    methods = registry.methods(COMMAND)
    engines = registry.engines()
    parser.add_argument("--method", choices=tuple(methods), default="fan",
                        help=f"what is minimised ({_choices_help(methods)}; default fan)")
    parser.add_argument("--engine", choices=tuple(engines), default="ase",
                        help=f"what minimises it ({_choices_help(engines)}; default ase)")
    parser.add_argument("--domain", default="circle", help=DOMAIN_HELP)
    parser.add_argument("--dx", type=positive(float), default=None,
                        help="background cell size, a length (default 1/256 in 2D, 1/32 in 3D; for files: "
                             "extent/128 or /32)")
    parser.add_argument("--h-over-dx", "--h", dest="h_over_dx", type=positive(float), default=2.6,
                        help=f"kernel support radius h in units of dx, > {H_MIN:g} (default 2.6; --h is the same "
                             "option: in Python, h= is a length)")
    parser.add_argument("--particle-volume", choices=PARTICLE_VOLUMES, default="dx",
                        help="particle volume v0 of the model and the metrics: dx = dx^dim (Fan Eq. 3.3, default), "
                             "V/N = domain volume / N (Eq. 3.2; total volume exact: use it for an SPH run)")
    parser.add_argument("--steps", type=non_negative_int, default=None,
                        help=f"maximum number of iterations (default {DEFAULT_STEPS}); given, it is a fixed length: "
                             "a run that does not reach --fmax then exits 0 (and records converged: false)")
    parser.add_argument("--optimizer", choices=OPTIMIZERS, default=None,
                        help="fan: Eq. 2.4 with step c*h; fire/fire2/bfgs/lbfgs: ASE optimisers scaled to SPH units "
                             "(drivers.make_optimizer). Default: fan for --engine ase, fire for --engine lammps "
                             "(which maps fire to its min_style and refuses the others: see --min-style)")
    stop = parser.add_mutually_exclusive_group()
    stop.add_argument("--fmax", type=non_negative_float, default=None,
                      help="stop when max |F| < FMAX, an absolute force as in ASE's Optimizer.run(fmax=...) "
                           "(default: run all --steps)")
    stop.add_argument("--fmax-rel", type=non_negative_float, default=None,
                      help="stop when max |F| < FMAX_REL x the initial max |F| (SPH forces are small: Fan's are "
                           "about 4e-3 on the default circle)")
    parser.add_argument("--dim", type=int, choices=(2, 3), default=None, help="dimension (default from the domain)")
    parser.add_argument("--jitter", type=float, default=0.1, help="initial random shift, fraction of dx (0.1)")
    parser.add_argument("--seed", type=int, default=0, help="random seed for the initial shift (0)")
    add_output_arguments(parser, "sphrelax_out", "relaxed.extxyz, relaxed.png, summary.json")
    add_progress_argument(parser)
    add_size_argument(parser)
    parser.add_argument("--strict", action="store_true",
                        help="set-up warnings become errors (exit 2), and a run that ends with particles outside "
                             "the domain exits with status 1")
    owners = {}
    for kind, objects in (("method", methods), ("engine", engines)):
        for name, obj in objects.items():
            if hasattr(obj, "add_arguments"):
                group = parser.add_argument_group(f"--{kind} {name}")
                obj.add_arguments(group)
                for action in group._group_actions:
                    owners[action.dest] = (kind, name, action.option_strings[0], action.default)
    parser.set_defaults(_owned_options=owners)


def _check_owned_options(args):
    """An option of another engine or method than the selected one is an error (e.g. --nprocs with --engine ase)."""
    for dest, (kind, name, flag, default) in getattr(args, "_owned_options", {}).items():
        selected = args.engine if kind == "engine" else args.method
        if name != selected and getattr(args, dest, default) != default:
            raise UsageError(f"{flag} applies to --{kind} {name} only; this run uses --{kind} {selected}")


def _setup_warnings(args, scene, quality_model_volume):
    """Warnings about settings that run but mislead (issue 10 item 5)."""
    notes = []
    if args.h_over_dx < H_TABLE:
        notes.append(f"--h-over-dx {args.h_over_dx:g}: fewer than about 6 neighbours per particle; kernel sums have "
                     f"large errors (Fan's Table 2 starts at h = {H_TABLE:g} dx)")
    if args.particle_volume == "dx" and scene.domain is not None:
        ratio = len(scene.atoms) * scene.dx**scene.dim / quality_model_volume
        if abs(ratio - 1.0) > VOLUME_TOL:
            notes.append(f"N dx^{scene.dim} = {ratio:.4f} x the domain volume: with v0 = dx^{scene.dim} every kernel "
                         f"sum is biased by {100 * (ratio - 1):+.1f} %; pass --particle-volume V/N (v0 = V/N)")
    return notes


def run(args):
    import warnings

    from ..analysis.quality import Quality

    t_start = time.perf_counter()
    with usage_errors():
        method = registry.methods(COMMAND)[args.method]
        engine = registry.engines()[args.engine]
        supported = getattr(engine, "methods", None)
        if supported is not None and args.method not in supported:
            raise UsageError(f"--engine {args.engine} supports --method {' or '.join(supported)}, "
                             f"got {args.method!r}")
        _check_owned_options(args)
        accepted = getattr(engine, "optimizers", OPTIMIZERS)  # None: the engine's check() decides
        if accepted is not None and args.optimizer is not None and args.optimizer not in accepted:
            raise UsageError(f"--engine {args.engine} accepts --optimizer {' or '.join(accepted)}, "
                             f"got {args.optimizer!r}")
        if args.h_over_dx <= H_MIN:
            raise UsageError(f"--h-over-dx (--h) must be > {H_MIN:g}, in units of dx, got {args.h_over_dx:g}: with "
                             "h <= dx the kernel support reaches no neighbour (Fan's Table 2 covers 1.5 to 3.5)")
        if not 0.0 <= args.jitter < 0.5:
            raise UsageError(f"--jitter must be in [0, 0.5) (fraction of dx), got {args.jitter:g}")
        notes = list(engine.check(args) or []) if hasattr(engine, "check") else []
        if args.optimizer is None:
            args.optimizer = getattr(engine, "default_optimizer", "fan")
        out = output_folder(args)
        steps_given = args.steps_given = args.steps is not None
        if not steps_given:
            args.steps = DEFAULT_STEPS
        scene = make_scene(args.domain, args.dim, args.dx, args.jitter, args.seed, max_particles=args.max_particles)
        h = args.h_over_dx * scene.dx
        calc = method.calculator(scene, h, args)
        quality = Quality(h, dx=particle_dx(scene, args), domain=scene.domain, dim=scene.dim)
        notes += _setup_warnings(args, scene, scene.domain.volume if scene.domain is not None else 1.0)
        for note in notes:
            if args.strict:
                raise UsageError(f"{note} (--strict makes this an error)")
            print(f"sphrelax relax: warning: {note}", file=sys.stderr)

    from ase.io import write

    from ..drivers.keep_inside import KeepInDomain
    from ..plotting import plot_particles

    atoms, dx, dim = scene.atoms, scene.dx, scene.dim
    before = quality.compute(atoms).summary()
    print(f"scene: {args.domain} ({dim}D), {len(atoms)} particles, dx = {dx:.6g}, h = {args.h_over_dx:g} dx, "
          f"v0 = {quality.v0:.6g} ({'dx^d' if args.particle_volume == 'dx' else 'V/N'}), method = {args.method}, "
          f"engine = {args.engine}, optimizer = {engine.describe(args)}")
    atoms.calc = calc
    calc.silence_scale_hint()  # the engines scale their optimisers: ASE's defaults are not in play
    e_before = atoms.get_potential_energy()
    t_relax = time.perf_counter()
    relaxed, steps_done, stop_reason = engine.relax(atoms, scene, h, args)
    t_relax = time.perf_counter() - t_relax
    driver = engine.describe(args)
    kept = [c for c in relaxed.constraints if isinstance(c, KeepInDomain)]
    if kept:
        relaxed.set_constraint([c for c in relaxed.constraints if not isinstance(c, KeepInDomain)])
    if relaxed is not atoms:
        relaxed.calc = calc
    atoms = relaxed
    e_after = atoms.get_potential_energy()
    after = quality.compute(atoms).summary()
    optimum = _lattice_optimum(args.h_over_dx, quality, dx, dim)

    out.mkdir(parents=True, exist_ok=True)
    atoms.new_array("volume", quality.volume_p)
    if quality.phi_p is not None:
        atoms.new_array("phi", quality.phi_p)
    atoms.info.update(dx=dx, h=h, steps=steps_done)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # extxyz: "no constraints written" and the like
        write(out / "relaxed.extxyz", atoms, format="extxyz")
    plot_particles(atoms, quality.volume_p / dx**dim, out / "relaxed.png", domain=scene.domain, dx=dx,
                   title=f"{args.domain}: h = {args.h_over_dx:g} dx, {steps_done} steps ({args.method}, {driver})",
                   label="particle volume 1/Σ_j W_ij  [dx^d]", range_mask=quality.interior_p)
    n_returned = sum(c.n_returned for c in kept)
    t_total = time.perf_counter() - STARTED
    summary = dict(scene=args.domain, dim=dim, n_particles=len(atoms), dx=dx, h_over_dx=args.h_over_dx,
                   particle_volume=args.particle_volume, v0=quality.v0,
                   method=args.method, engine=args.engine, optimizer=driver, steps=steps_done,
                   stop_reason=stop_reason, energy_before=e_before, energy_after=e_after,
                   quality_before=before, quality_after=after, lattice_optimum=optimum,
                   moves_kept_inside=n_returned, wall_time_s=t_relax, command_time_s=t_total,
                   setup_time_s=t_start - STARTED)
    has_rule = args.fmax is not None or args.fmax_rel is not None
    converged = has_rule and steps_done < args.steps  # the engine stopped before its cap: max |F| < fmax
    if converged:
        reason = stop_reason
    elif has_rule:
        reason = f"max |F| did not fall below the --fmax criterion within {args.steps} steps"
    else:
        reason = f"no stopping rule (no --fmax or --fmax-rel): ran {steps_done} steps"
    summary.update(converged=converged, convergence_reason=reason, **provenance(args, COMMAND))
    (out / "summary.json").write_text(json.dumps(summary, indent=2))

    print(f"stopped after {steps_done} steps: {stop_reason}")
    print(f"{getattr(method, 'energy_label', 'energy')}: {e_before:.6e} -> {e_after:.6e}")
    _print_quality(before, after)
    if optimum is not None:
        print(f"{'lattice optimum 1/v_c':32s} {'':>12s} {optimum['inverse_v_c']:12.5f}   ({optimum['pattern']} at "
              f"h = {optimum['h_over_dp']:.4g} dp, dp = v0^(1/{dim}); a relaxed interior has mean Σ V W near it)")
    if n_returned:
        print(f"{n_returned} particle move(s) were cut at the boundary to keep particles inside (KeepInDomain)")
    print(f"wall time: relaxation {t_relax:.1f} s; whole command {t_total:.1f} s "
          "(also imports, set-up, numba compilation, metrics, figure and files)")
    print(f"wrote {out / 'relaxed.extxyz'}, {out / 'relaxed.png'}, {out / 'summary.json'}")
    n_out = after.get("n_outside", 0)
    if n_out:
        print(f"WARNING: {n_out} particle(s) ended outside the domain (max φ = {after['max_phi_over_dp']:.3g} dp)"
              + ("; exit status 1 (--strict)" if args.strict else "; --strict makes this exit status 1"))
        return 1 if args.strict else 0
    if has_rule and not converged:
        if steps_given:
            print(f"sphrelax relax: warning: not converged (--steps was given: exit 0): {reason}", file=sys.stderr)
            return 0
        print(f"sphrelax relax: not converged: {reason} (exit {EXIT_NOT_CONVERGED})", file=sys.stderr)
        return EXIT_NOT_CONVERGED
    return 0


def _lattice_optimum(h_over_dx, quality, dx, dim):
    """Fan's lattice optimum (Sec. 5) at the run's h / dp: pattern, v_c and 1/v_c (None outside 2D/3D)."""
    from ..analysis.pattern_prediction import predict_pattern

    if dim not in (2, 3):
        return None
    h_over_dp = h_over_dx * dx / quality.v0 ** (1.0 / dim)
    pattern, values = predict_pattern(h_over_dp, dim, return_values=True)
    v_c = max(v for v, _ in values.values())
    return dict(pattern=pattern, h_over_dp=h_over_dp, v_c=v_c, inverse_v_c=1.0 / v_c)


def _progress(opt, atoms, steps, label, disable=None, file=None):
    from tqdm.auto import tqdm

    bar = tqdm(total=steps, desc=label, unit="step", disable=disable, mininterval=0.5, file=file)

    def update():  # observers run at step 0 too: follow opt.nsteps, not the number of calls
        bar.update(opt.nsteps - bar.n)
        if opt.nsteps % 25 == 0:
            bar.set_postfix(E=f"{atoms.get_potential_energy():.6e}")

    opt.attach(update, interval=1)
    return bar


def _cell(value):
    if value is None:
        return f"{'n/a':>12s}"
    return f"{value:12.4g}"


def _print_quality(before, after):
    rows = [("mean Σ V W (interior)", "kernel_sum_mean"),
            ("mean |Σ V W - 1| (interior)", "kernel_sum_error_mean"),
            ("max  |Σ V W - 1| (interior)", "kernel_sum_error_max"),
            ("mean h|Σ V ∇W|  (interior)", "gradient_error_mean"),
            ("max  h|Σ V ∇W|  (interior)", "gradient_error_max"),
            ("boundary layer -φ/dp mean", "boundary_distance_mean"),
            ("boundary layer -φ/dp min", "boundary_distance_min"),
            ("max  |Σ V W + 1 - γ - 1| (walls)", "near_wall_kernel_sum_error_max"),
            ("std   Σ V W + 1 - γ     (walls)", "near_wall_kernel_sum_std"),
            ("max  h|Σ V ∇W - ∇γ|    (walls)", "near_wall_gradient_error_max"),
            ("max φ/dp (escape if > 0)", "max_phi_over_dp"),
            ("particles outside (φ > 0)", "n_outside")]
    print(f"{'metric':32s} {'initial':>12s} {'relaxed':>12s}   (n/a: no particle in that set)")
    for label, key in rows:
        if key in after:
            print(f"{label:32s} {_cell(before.get(key))} {_cell(after.get(key))}")
