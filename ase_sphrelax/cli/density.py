"""equal-mass particles for a target density (ALARIC, Vela Vela et al.)

Runs ALARIC's dynamics (isothermal SPH in the potential of the target, friction, viscosity,
velocity stops) from N / p^K particles with K splitting stages (p = 3, 4, 5 in 1D, 2D, 3D; e.g.
--n 303 --split 1 starts from 101 in 1D), then polishes with LBFGS on the least-squares
potential (1D; opt-in with --polish in 2D/3D, where it pairs particles). 1D runs on the periodic
interval [-1, 1); 2D/3D in the unit disc/ball (or --domain).
Writes relaxed.extxyz (masses, H and rho per particle), density.png, trace.json and summary.json
(final epsilon of Eq. 45 under "epsilon", the Eq. 48 minimum where known, wall time, "converged" and
why) to --out.

Exit status: 0 when the run converged, or when --max-steps was given (a fixed length; an unconverged
run then warns); 3 when a run of the default length ends unconverged or degenerate; 2 for a usage error.
"""
from __future__ import annotations

import json
import sys
import time

from .common import (EXIT_NOT_CONVERGED, add_output_arguments, add_progress_argument, output_folder, provenance,
                     show_progress)
from .usage import UsageError, non_negative_int, positive, usage_errors

MAX_STEPS = 50000  # the dynamics' default step cap; reaching it unconverged exits EXIT_NOT_CONVERGED

__all__ = ["add_arguments", "run", "load_profile"]

PROFILE_HELP = ("eq46 (Eq. 46, with --delta), eq49 (Eq. 49, 2D, with --p), uniform, or module:function "
                "(a vectorised callable (N, dim) -> (N,); the module must be importable: put its folder on "
                "PYTHONPATH, e.g. PYTHONPATH=. for ./module.py)")


def add_arguments(parser):
    parser.add_argument("--profile", default="eq46", help=f"target density: {PROFILE_HELP} (default eq46)")
    parser.add_argument("--delta", type=float, default=0.1, help="Delta of Eq. 46: rho*(0) = Delta (default 0.1)")
    parser.add_argument("--p", type=float, default=1.0, help="p of Eq. 49 (default 1)")
    parser.add_argument("--dim", type=int, choices=(1, 2, 3), default=1, help="dimension (default 1)")
    parser.add_argument("--n", type=positive(int), default=303, help="final number of particles (default 303)")
    parser.add_argument("--split", type=non_negative_int, default=1,
                        help="splitting stages K: the run starts from n / p^K particles (default 1)")
    parser.add_argument("--domain", default="ball",
                        help="2D/3D only: ball (the unit disc or ball, default) or a sphrelax relax domain "
                             "(circle, box, sphere, an edge file, an .stl mesh)")
    parser.add_argument("--boundary", choices=("auto", "wall", "mirror"), default="auto",
                        help="edge treatment in 2D/3D: mirror ghosts that complete the kernels at a ball's or a "
                             "convex polygon's boundary, or wall (truncated kernels); auto (default): mirror "
                             "where the domain allows it, else wall")
    parser.add_argument("--wall-form", choices=("linear", "quadratic"), default="linear",
                        help="2D/3D: the domain wall's energy per particle outside, linear m c^2 phi/L (default, "
                             "L = 0.1 (V/N)^(1/d)) or quadratic m c^2 phi^2/(2 L^2) (L = 0.5 (V/N)^(1/d): no force "
                             "jump at the boundary, reproductions/alaric-fig8-3d-isolate)")
    parser.add_argument("--form", choices=("log", "paper", "squares"), default="log",
                        help="force of the dynamics: log (the ALARIC potential, default), paper (Eq. 29 with the "
                             "background pressure c^2 max(rho* - rho)_+ and eta = 2.5, "
                             "reproductions/alaric-eq29-stability), squares")
    parser.add_argument("--finish", choices=("none", "squares"), default="none",
                        help="squares: after the log potential stops by epsilon_dot, continue the dynamics on the "
                             "least-squares potential (fixed point rho = rho*; it empties density wells, so "
                             "check the well); none (default)")
    polish = parser.add_mutually_exclusive_group()
    polish.add_argument("--polish", dest="polish", action="store_true", default=None,
                        help="LBFGS polish on the least-squares potential after the dynamics (default in 1D only: "
                             "in 2D/3D it lowers epsilon by pairing particles)")
    polish.add_argument("--no-polish", dest="polish", action="store_false", help="no polish")
    parser.add_argument("--polish-steps", type=non_negative_int, default=4000,
                        help="LBFGS steps of the least-squares polish (4000)")
    parser.add_argument("--max-steps", type=positive(int), default=None,
                        help="step cap of the dynamics (default 50000; given: a fixed length, exit 0 even "
                             "unconverged); it changes nothing else: each pre-split stage still lasts at most "
                             "50000/(K+1) steps, and a cap reached before the last split splits the particles "
                             "there, so the result has --n particles)")
    parser.add_argument("--max-wall", type=positive(float), default=None,
                        help="wall-time cap of the dynamics in seconds (a cap like --max-steps: exit 0 even unconverged)")
    parser.add_argument("--eps-min", type=positive(float), default=1e-8, help="stop at epsilon below this (1e-8)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the start jitter and split orientations (0)")
    add_output_arguments(parser, "sphrelax_density", "relaxed.extxyz, density.png, trace.json, summary.json")
    add_progress_argument(parser)


def load_profile(name, dim, delta=0.1, p=1.0):
    """(density, gradient or None, Eq. 48 applies) for a built-in name or ``module:function``."""
    from ..models import alaric as model

    if name == "eq46":
        density, gradient = model.eq46(delta)
        return density, gradient, True
    if name == "eq49":
        if dim != 2:
            raise UsageError(f"--profile eq49 is 2D (Eq. 49 in the unit disc), got --dim {dim}")
        density, gradient = model.eq49(p)
        return density, gradient, False
    if name == "uniform":
        density, gradient = model.uniform(1.0)
        return density, gradient, False
    if ":" not in name:
        raise UsageError(f"--profile must be eq46, eq49, uniform or module:function, got {name!r}")
    import importlib

    module_name, _, attr = name.partition(":")
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise UsageError(f"--profile {name!r}: cannot import {module_name!r} ({exc}); the module must be importable: "
                         f"put its folder on PYTHONPATH, e.g. PYTHONPATH=. for ./{module_name.replace('.', '/')}.py"
                         ) from None
    try:
        obj = getattr(module, attr)
    except AttributeError as exc:
        raise UsageError(f"--profile {name!r}: cannot load it ({exc})") from None
    if not callable(obj):
        raise UsageError(f"--profile {name!r} is not callable")
    return obj, getattr(obj, "gradient", None), False


def run(args):
    t_start = time.perf_counter()
    with usage_errors():
        import numpy as np

        from ..drivers.alaric_dynamics import start_atoms
        from ..splitting import SPLIT_COUNT

        dim = args.dim
        out = output_folder(args)
        density, gradient, eq48 = load_profile(args.profile, dim, args.delta, args.p)
        p = SPLIT_COUNT[dim]
        n0 = int(round(args.n / p**args.split))
        if n0 * p**args.split != args.n:
            raise UsageError(f"--n {args.n} is not divisible by p^K = {p}^{args.split} (p = {p} in {dim}D)")
        domain = None
        if dim == 1 and args.boundary == "mirror":
            raise UsageError("--boundary mirror is for --dim 2 or 3 (1D runs on a periodic interval, no boundary)")
        if dim == 1 and args.wall_form != "linear":
            raise UsageError(f"--wall-form is for --dim 2 or 3 (1D runs on a periodic interval, no boundary), got "
                             f"--wall-form {args.wall_form} with --dim 1")
        if dim == 1 and args.domain != "ball":
            raise UsageError(f"--domain is for --dim 2 or 3 (1D runs on the periodic interval [-1, 1)), "
                             f"got --domain {args.domain!r} with --dim 1")
        if dim > 1 and args.domain != "ball":
            from .scene import make_scene

            domain = make_scene(args.domain, dim=dim).domain
            if domain is None:
                raise UsageError("--domain periodic is not supported by sphrelax density")
            from ..models.alaric import mirror_supported

            if args.boundary == "mirror" and not mirror_supported(domain):
                raise UsageError(f"--boundary mirror needs a ball or a convex polygon domain (one loop), got "
                                 f"--domain {args.domain!r}; use --boundary wall")
        atoms, origin, domain = start_atoms(n0, dim, domain=domain, seed=args.seed)
        # check the target on the start before any step (bad output shapes, NaN, negative values)
        from ..models.alaric import Target

        probe = Target(density, dim, gradient).values(np.ascontiguousarray(atoms.positions[:, :dim] + origin))
        if not np.any(probe > 0):
            raise ValueError("the target density is zero at every starting particle")
        if len(atoms) * p**args.split < 2:
            raise UsageError("--n is too small")

    from ase.io import write

    from ..drivers.alaric_dynamics import relax_density

    do_polish = (dim == 1 if args.polish is None else args.polish) and args.polish_steps > 0
    print(f"ALARIC: profile {args.profile} ({dim}D), {len(atoms)} particles x {p}^{args.split} -> {args.n}, "
          f"form {args.form}{' + least-squares polish' if do_polish else ''}")

    eps_teo = None
    if eq48:
        from ..analysis.alaric import alaric_min_error

        eps_teo = alaric_min_error(args.n, args.delta, dim)
    result = relax_density(atoms, density, dim, target_gradient=gradient, splits=args.split, domain=domain,
                           origin=origin, form=args.form, polish=do_polish, boundary=args.boundary,
                           wall_form=args.wall_form,
                           finish=args.finish if args.form == "log" else "none",
                           polish_steps=args.polish_steps,
                           max_steps=MAX_STEPS if args.max_steps is None else args.max_steps,
                           # the pre-split stages' length follows the default cap, not --max-steps (a cap only)
                           stage_steps=MAX_STEPS // (args.split + 1) if args.split else None, split_at_cap=True,
                           **({} if args.max_wall is None else dict(max_wall=args.max_wall)),
                           eps_min=args.eps_min, progress=show_progress(args), seed=args.seed, epsilon_min=eps_teo)
    atoms = result["atoms"]
    calc = result["calculator"]
    res = calc.results
    eps = float(result["epsilon"])
    diagnostics = result["diagnostics"]
    wall = time.perf_counter() - t_start
    out.mkdir(parents=True, exist_ok=True)
    atoms.new_array("h", np.asarray(res["smoothing_lengths"], dtype=float))
    atoms.new_array("rho", np.asarray(res["density"], dtype=float))
    atoms.new_array("target", np.asarray(res["target"], dtype=float))
    atoms.info.update(origin=origin.tolist(), epsilon=eps, profile=args.profile)
    shown = atoms.copy()
    shown.positions[:, :dim] = calc.points(atoms.positions, atoms)  # in the target's frame
    write(out / "relaxed.extxyz", shown, format="extxyz")
    _plot(shown, res, dim, out / "density.png", f"{args.profile}: N = {len(atoms)}, eps = {eps:.2e}")
    (out / "trace.json").write_text(json.dumps(result["trace"], indent=1))
    summary = dict(profile=args.profile, delta=args.delta if args.profile == "eq46" else None,
                   p=args.p if args.profile == "eq49" else None, dim=dim, n=len(atoms), splits=args.split,
                   form=args.form, boundary=calc.parameters.boundary, wall_form=calc.parameters.wall_form if dim > 1 else None,
                   finish=args.finish, polish=do_polish,
                   epsilon=eps,
                   epsilon_dynamics=float(result["epsilon_dynamics"]), epsilon_teo_min=eps_teo,
                   steps=int(result["steps"]), force_calls=int(result["force_calls"]),
                   stop_reason=result["stop_reason"], converged=result["converged"],
                   convergence_reason=result["convergence_reason"],
                   max_relative_error=diagnostics["max_relative_error"],
                   zero_target_particles=diagnostics["zero_target_particles"],
                   zero_region_particles=diagnostics["zero_region_particles"], regions=diagnostics["regions"],
                   n_outside=int(result["n_outside"]),
                   mass=float(calc.mass), wall_time_s=wall,
                   **provenance(args, "density"))
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    print(f"dynamics: {result['steps']} steps, stopped by {result['stop_reason']}, "
          f"epsilon {result['epsilon_dynamics']:.3e}")
    print(f"final epsilon (Eq. 45): {eps:.3e}" + (f"   (Eq. 48 minimum {eps_teo:.2e})" if eps_teo is not None else ""))
    print(f"max |rho/rho* - 1|: {diagnostics['max_relative_error']}; per decade of rho*/max: "
          + ", ".join(f"[{r['target_range'][0]:.0e}, {r['target_range'][1]:.0e}] n={r['n']} eps={r['epsilon']:.2e} "
                      f"rms|rho/rho*-1|={r['rms_relative_error']:.2e}" for r in diagnostics["regions"]))
    print(("converged: " if result["converged"] else "NOT CONVERGED: ") + result["convergence_reason"])
    print(f"wall time: {wall:.1f} s")
    print(f"wrote {out / 'relaxed.extxyz'}, {out / 'density.png'}, {out / 'trace.json'}, {out / 'summary.json'}")
    if result["converged"]:
        return 0
    if args.max_steps is not None or args.max_wall is not None:  # a fixed length was asked for
        print(f"sphrelax density: warning: not converged (--max-steps or --max-wall was given: exit 0): "
              f"{result['convergence_reason']}", file=sys.stderr)
        return 0
    print(f"sphrelax density: not converged: {result['convergence_reason']} (exit {EXIT_NOT_CONVERGED})",
          file=sys.stderr)
    return EXIT_NOT_CONVERGED


def _plot(atoms, res, dim, path, title):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    x = atoms.positions[:, :dim]
    fig, ax = plt.subplots(figsize=(6, 4.5) if dim == 1 else (5.5, 5))
    if dim == 1:
        order = np.argsort(x[:, 0])
        ax.plot(x[order, 0], res["target"][order], "k-", lw=1, label="target rho*")
        ax.plot(x[order, 0], res["density"][order], ".", ms=3, label="SPH rho_a")
        ax.set_xlabel("x")
        ax.set_ylabel("density")
        ax.legend()
    else:
        r = np.linalg.norm(x, axis=1)
        if dim == 2:
            sc = ax.scatter(x[:, 0], x[:, 1], c=res["density"], s=4, cmap="viridis")
            ax.set_aspect("equal")
            fig.colorbar(sc, ax=ax, label="SPH rho_a")
        else:
            ax.plot(r, res["target"], "k.", ms=1, label="target rho*")
            ax.plot(r, res["density"], ".", ms=2, label="SPH rho_a")
            ax.set_xlabel("r")
            ax.legend()
    ax.set_title(title)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
