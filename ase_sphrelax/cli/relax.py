"""relax particles in a domain (default: Fan et al. Appendix A circle)

With no options this runs Fan et al.'s Appendix A scene: a circle centred
(0.5, 0.5) of radius 0.2, dx = 1/256 (8224 particles at background-cell centres
with a small random shift), h = 2.6 dx, Eq. 2.4 updates with c = 0.01.
Writes relaxed.extxyz, relaxed.png and summary.json to --out.

--method picks the model (the calculator whose energy is relaxed), --engine
what minimises it; both come from registries (ase_sphrelax.cli.registry).
"""
from __future__ import annotations

import json
import time
from pathlib import Path

from ..drivers.optimizers import DEFAULT_C, OPTIMIZERS
from . import registry
from .scene import DOMAIN_HELP, make_scene
from .usage import UsageError, non_negative_int, positive, usage_errors

__all__ = ["add_arguments", "run", "FanMethod", "AseEngine"]

COMMAND = "relax"


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

        return FanCalculator(h=h, dx=scene.dx, domain=scene.domain, dim=scene.dim)


class AseEngine:
    """the method's calculator with an optimiser in Python (Eq. 2.4 or an ASE optimiser)

    A relax engine provides ``relax(atoms, scene, h, args) -> (atoms, steps, stop_reason)``
    and ``describe(args)`` (the driver's name for the log), and optionally
    ``add_arguments(parser)``, ``methods`` (the method names it supports; None: all)
    and ``check(args)`` (set-up phase: raise UsageError or ValueError).
    """

    methods = None

    @staticmethod
    def add_arguments(parser):
        parser.add_argument("--optimizer", choices=OPTIMIZERS, default="fan",
                            help="fan: Eq. 2.4 with step c*h (default); fire/bfgs/lbfgs: ASE optimisers")
        defaults = ", ".join(f"{c:g} for {name}" for name, c in DEFAULT_C.items())
        parser.add_argument("--c", type=positive(float), default=None,
                            help="step scale: Eq. 2.4 coefficient for fan; first step c*h for the ASE optimisers "
                                 f"(default {defaults})")
        parser.add_argument("--fmax", type=float, default=0.0,
                            help="stop when max |F| < fmax, in units of the initial max |F| "
                                 "(default 0: run all steps)")

    @staticmethod
    def describe(args):
        return args.optimizer

    @staticmethod
    def relax(atoms, scene, h, args):
        import numpy as np

        from ..drivers.optimizers import make_optimizer

        f0 = float(np.linalg.norm(atoms.get_forces(), axis=1).max())
        opt = make_optimizer(args.optimizer, atoms, c=args.c)
        bar = _progress(opt, atoms, args.steps, f"relax ({args.optimizer})")
        try:
            converged = opt.run(fmax=args.fmax * f0, steps=args.steps)
        finally:
            bar.close()
        stop_reason = (f"converged: max |F| < {args.fmax:g} x initial" if converged
                       else f"reached --steps {args.steps}")
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
                        help="background cell size (default 1/256 in 2D, 1/32 in 3D; for files: extent/128 or /32)")
    parser.add_argument("--h", type=positive(float), default=2.6, help="kernel support radius in units of dx (2.6)")
    parser.add_argument("--steps", type=non_negative_int, default=2000, help="maximum number of steps (2000)")
    parser.add_argument("--dim", type=int, choices=(2, 3), default=None, help="dimension (default from the domain)")
    parser.add_argument("--jitter", type=float, default=0.1, help="initial random shift, fraction of dx (0.1)")
    parser.add_argument("--seed", type=int, default=0, help="random seed for the initial shift (0)")
    parser.add_argument("--out", default="sphrelax_out", help="output folder (relaxed.extxyz, relaxed.png, summary.json)")
    for kind, objects in (("method", methods), ("engine", engines)):
        for name, obj in objects.items():
            if hasattr(obj, "add_arguments"):
                obj.add_arguments(parser.add_argument_group(f"--{kind} {name}"))


def run(args):
    from ..analysis.quality import Quality

    t_start = time.perf_counter()
    with usage_errors():
        method = registry.methods(COMMAND)[args.method]
        engine = registry.engines()[args.engine]
        supported = getattr(engine, "methods", None)
        if supported is not None and args.method not in supported:
            raise UsageError(f"--engine {args.engine} supports --method {' or '.join(supported)}, "
                             f"got {args.method!r}")
        if hasattr(engine, "check"):
            engine.check(args)
        out = Path(args.out)
        if out.exists() and not out.is_dir():
            raise UsageError(f"--out {args.out!r} exists and is not a folder")
        scene = make_scene(args.domain, args.dim, args.dx, args.jitter, args.seed)
        h = args.h * scene.dx
        calc = method.calculator(scene, h, args)
        quality = Quality(h, dx=scene.dx, domain=scene.domain, dim=scene.dim)

    from ase.io import write

    from ..plotting import plot_particles

    atoms, dx, dim = scene.atoms, scene.dx, scene.dim
    driver = engine.describe(args)
    before = quality.compute(atoms).summary()
    print(f"scene: {args.domain} ({dim}D), {len(atoms)} particles, dx = {dx:.6g}, h = {args.h:g} dx, "
          f"method = {args.method}, engine = {args.engine}, optimizer = {driver}")
    atoms.calc = calc
    e_before = atoms.get_potential_energy()
    relaxed, steps_done, stop_reason = engine.relax(atoms, scene, h, args)
    if relaxed is not atoms:
        relaxed.calc = calc
    atoms = relaxed
    e_after = atoms.get_potential_energy()
    after = quality.compute(atoms).summary()
    wall = time.perf_counter() - t_start

    out.mkdir(parents=True, exist_ok=True)
    atoms.new_array("volume", quality.volume_p)
    if quality.phi_p is not None:
        atoms.new_array("phi", quality.phi_p)
    atoms.info.update(dx=dx, h=h, steps=steps_done)
    write(out / "relaxed.extxyz", atoms, format="extxyz")
    plot_particles(atoms, quality.volume_p / dx**dim, out / "relaxed.png", domain=scene.domain, dx=dx,
                   title=f"{args.domain}: h = {args.h:g} dx, {steps_done} steps ({args.method}, {driver})",
                   label="particle volume 1/Σ_j W_ij  [dx^d]", range_mask=quality.interior_p)
    summary = dict(scene=args.domain, dim=dim, n_particles=len(atoms), dx=dx, h_over_dx=args.h,
                   method=args.method, engine=args.engine, optimizer=driver, steps=steps_done,
                   stop_reason=stop_reason, energy_before=e_before, energy_after=e_after,
                   quality_before=before, quality_after=after, wall_time_s=wall)
    (out / "summary.json").write_text(json.dumps(summary, indent=2))

    print(f"stopped after {steps_done} steps: {stop_reason}")
    print(f"{getattr(method, 'energy_label', 'energy')}: {e_before:.6e} -> {e_after:.6e}")
    _print_quality(before, after)
    print(f"wall time: {wall:.1f} s")
    print(f"wrote {out / 'relaxed.extxyz'}, {out / 'relaxed.png'}, {out / 'summary.json'}")
    return 0


def _progress(opt, atoms, steps, label):
    from tqdm.auto import tqdm

    bar = tqdm(total=steps, desc=label, unit="step", disable=None, mininterval=0.5)

    def update():
        bar.update(1)
        if opt.nsteps % 25 == 0:
            bar.set_postfix(E=f"{atoms.get_potential_energy():.6e}")

    opt.attach(update, interval=1)
    return bar


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
