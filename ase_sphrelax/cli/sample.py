"""sample an unnormalised density with SPH-ParVI (samples .npy + extxyz, trace JSON, plot)

Examples::

    sphrelax sample --target banana --n 500 --out banana_out
    sphrelax sample --target mymodule:log_density --score mymodule:score --dim 3 --n 1000 --steps 800

``--target`` is a built-in target (gaussian, correlated, ring8, banana, donut, funnel, gaussian10d,
logistic) or ``module:function``, a vectorised log-density ``(M, d) -> (M,)`` (``--dim`` is then
required; ``--score module:function`` adds its gradient, otherwise it is taken by central differences).
The run uses SPH-ParVI's default configuration, the API's (``ase_sphrelax.sampling.sampler.DEFAULTS``: score
force, isothermal EOS with alpha = c0^2, adaptive h with about 12 neighbours in 2D, local time steps, the critical
friction, the per-particle score hold, 1000 score evaluations per particle) unless options change it;
``--variant classic`` is the configuration that was the default before (``ase_sphrelax.sampling.CLASSIC``).
Writes ``OUT/samples.npy`` (M, d), ``OUT/samples.extxyz`` (particles as atoms: positions for d <= 3, the
per-atom array ``sample`` for any d), ``OUT/trace.json`` (the run's trace and parameters), ``OUT/summary.json``
(every parameter, the seed, the target, ``converged``, ``at_rest``, the verdict's figures and the reason) and
``OUT/samples.png`` (2D: particles over the target's contours; 1D: histogram and density; d > 2: pair marginals
of the first axes).

Convergence: ``converged`` needs the fluid at rest (the drift of the ensemble's mean and covariance and of
its kinetic energy over the last half of the run, against their Monte-Carlo standard errors,
``ase_sphrelax.sampling.convergence``) and the samples passing a check against the target
(``ase_sphrelax.sampling.verdict``: a short exact MALA chain from the particles that must not move their means
and second moments beyond a calibrated bound, an importance-sampling check that the particles' shares beyond
whitened radii 2-5 match the target's, and a mode search whose modes the particles must not miss; a missed mode
restarts the run once from the modes found). summary.json has ``at_rest``, ``check_passed`` and the checks'
figures under ``verdict``. Before any work the target is checked: a score that points
away from the mass everywhere, or that does not match the central differences of ``--target``'s
log-density, is a usage error; the initial particles are placed at the scale (and mode) found from
the score unless ``--init-scale`` is given.

Variants: ``--variant whiten+mala`` adds options to the default (``ase_sphrelax.sampling.sampler.variant_options``;
the tokens are listed in ``--help``, joined by ``+``); none changes the stationary density.

Length: the API's rule: ``--steps`` (default 1000) score evaluations per particle with the default per-particle
hold (SPH steps with ``--variant classic`` or ``score_every=1``). ``--max-steps K`` (only with a fixed score
cadence, e.g. ``--variant classic``) doubles the length while the run is not at rest, up to K.

Exit status: 0 when the run converged, or when ``--steps`` fixed the length (an unconverged run then warns
and records ``converged: false``); 3 when it did not converge without ``--steps``, or the run diverged (the
last line says why, summary.json has the reason); 2 for a usage error (one line, before any work).
"""
from __future__ import annotations


from .common import add_output_arguments, add_progress_argument, output_folder, provenance, show_progress
from .usage import UsageError, positive, usage_errors

__all__ = ["add_arguments", "run", "EXIT_NOT_CONVERGED", "DEFAULT_STEPS"]

#: exit status of a run of the default length that did not converge (or diverged)
EXIT_NOT_CONVERGED = 3
#: the length of a run when ``--steps`` is not given: the API's (``sampler.DEFAULTS["steps"]``, 1000 score evaluations
#: per particle; a variant that sets its own, as ``classic``'s 600 SPH steps, keeps it)
DEFAULT_STEPS = 1000

FORMULATIONS = ("force", "pressure-log", "pressure-inverse")
EOS = ("isothermal", "tait")


def _friction(text):
    if text == "critical":
        return text
    return float(text)


def _h(text):
    if text == "adaptive":
        return text
    return positive(float)(text)


def add_arguments(parser):
    parser.add_argument("--target", required=True, help="built-in target name or module:function (log-density)")
    parser.add_argument("--score", default=None, help="module:function, the score of a module:function target")
    parser.add_argument("--n", type=positive(int), default=500, help="number of particles (default 500)")
    parser.add_argument("--dim", type=positive(int), default=None, help="dimension (built-in targets: their own)")
    parser.add_argument("--formulation", choices=FORMULATIONS, default="force",
                        help="force: body force along the score (Algorithm 2, default); pressure-log / "
                             "pressure-inverse: external pressure -alpha log p or 1/(alpha p) (Algorithm 1)")
    parser.add_argument("--eos", choices=EOS, default="isothermal",
                        help="isothermal P = c0^2 rho (default: its stationary density is the target when "
                             "alpha = c0^2) or tait")
    parser.add_argument("--alpha", type=positive(float), default=1.0, help="target amplification (default 1)")
    parser.add_argument("--c0", type=positive(float), default=None, help="sound speed (default sqrt(alpha))")
    parser.add_argument("--support", type=_h, default="adaptive",
                        help="kernel support radius h as a length (not in units of dx, as relax's --h), or "
                             "'adaptive' (default: per-particle H from the density)")
    parser.add_argument("--steps", type=positive(int), default=None,
                        help=f"the run's length, given: the run exits 0 even if it did not converge (default: the "
                             f"API's, 1000 score evaluations per particle, 600 SPH steps with --variant classic; "
                             f"exit {EXIT_NOT_CONVERGED} if not converged)")
    parser.add_argument("--max-steps", type=positive(int), default=None,
                        help="the stopping rule: double the length while the fluid is not at rest, up to this "
                             "(only with a fixed score cadence, e.g. --variant classic; default: no doubling)")
    parser.add_argument("--friction", type=_friction, default=None,
                        help="drag coefficient, or 'critical' (a drag critical along each principal direction of "
                             "the target's curvature; the default; with --variant classic the default is 1 / the "
                             "target's scale found from its score: 1 for a unit target)")
    parser.add_argument("--variant", default="default", help=_variant_help())
    parser.add_argument("--rule", choices=("final", "optimal"), default="final",
                        help="which state to return: final (default) or the paper's optimal state (maximum mean "
                             "density; measured 7-400x worse, see reproductions/parvi-baselines)")
    parser.add_argument("--init-scale", type=positive(float), default=None,
                        help="sd of the initial N(0, s^2 I) (default: centre and per-axis scale found from the "
                             "target's score by a short mode search)")
    parser.add_argument("--seed", type=int, default=0, help="random seed of the initial particles (default 0)")
    add_output_arguments(parser, "sample_out", "samples.npy, samples.extxyz, trace.json, summary.json, samples.png")
    add_progress_argument(parser)


def _variant_help():
    from ..sampling.configurations import VARIANT_NUMBERS, VARIANT_TOKENS

    return (f"SPH-ParVI variant: tokens joined by '+', each one of {', '.join(VARIANT_TOKENS)} or name=number for "
            f"{', '.join(VARIANT_NUMBERS)} (e.g. whiten+mala; default: default, the API's default configuration; "
            f"classic: the configuration that was the default before)")


def _load_callable(spec, what):
    import importlib

    module_name, sep, attr = spec.partition(":")
    if not sep or not module_name or not attr:
        raise UsageError(f"{what} must be a built-in name or module:function, got {spec!r}")
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise UsageError(f"{what}: cannot import module {module_name!r} ({exc})") from None
    fn = getattr(module, attr, None)
    if not callable(fn):
        raise UsageError(f"{what}: {module_name!r} has no function {attr!r}")
    return fn


def _plot(path, x, log_density):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    d = x.shape[1]
    if d == 1:
        fig, ax = plt.subplots(figsize=(4.5, 3))
        ax.hist(x[:, 0], bins=40, density=True, color="C0", alpha=0.6, label="particles")
        if log_density is not None:
            g = np.linspace(x.min() - 1, x.max() + 1, 400)[:, None]
            p = np.exp(log_density(g) - log_density(g).max())
            ax.plot(g[:, 0], p / (p.sum() * (g[1, 0] - g[0, 0])), color="C3", label="target")
        ax.legend(fontsize=8)
    elif d == 2:
        fig, ax = plt.subplots(figsize=(4.5, 4.5))
        if log_density is not None:
            lo, hi = np.percentile(x, 0.5, axis=0), np.percentile(x, 99.5, axis=0)
            pad = 0.15 * (hi - lo)
            gx, gy = np.meshgrid(np.linspace(lo[0] - pad[0], hi[0] + pad[0], 200),
                                 np.linspace(lo[1] - pad[1], hi[1] + pad[1], 200))
            lp = log_density(np.stack([gx.ravel(), gy.ravel()], 1)).reshape(gx.shape)
            ax.contour(gx, gy, np.exp(lp - lp.max()), levels=8, colors="0.6", linewidths=0.7)
        ax.scatter(x[:, 0], x[:, 1], s=3, color="C3")
        ax.set_aspect("equal", adjustable="datalim")
    else:
        k = min(d, 5)
        fig, axes = plt.subplots(k, k, figsize=(1.8 * k, 1.8 * k))
        for i in range(k):
            for j in range(k):
                ax = axes[i, j]
                if i == j:
                    ax.hist(x[:, i], bins=30, color="C0")
                else:
                    ax.scatter(x[:, j], x[:, i], s=1, color="C3")
                ax.set_xticks([])
                ax.set_yticks([])
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def run(args):
    import json

    import numpy as np

    import sys
    import warnings

    from ..checks import NotConvergedWarning
    from ..sampling.sampler import DEFAULTS, ParVIDivergence, ParVISampler, variant_options
    from ..sampling.targets import TARGET_NAMES, get_target

    with usage_errors():
        if args.target in TARGET_NAMES:
            target = get_target(args.target)
            if args.dim is not None and args.dim != target.dim:
                raise UsageError(f"--dim {args.dim} does not match target {args.target!r}, which is {target.dim}-D")
            if args.score is not None:
                raise UsageError("--score is only for module:function targets (built-ins have their own)")
            log_density, score, dim = target.log_density, target.score, target.dim
        else:
            log_density = _load_callable(args.target, "--target")
            score = _load_callable(args.score, "--score") if args.score else None
            if args.dim is None:
                raise UsageError("--dim is required with a module:function target")
            dim = args.dim
        fixed = args.steps is not None and args.max_steps is None
        if isinstance(args.friction, float) and args.friction < 0:
            raise UsageError(f"--friction must be >= 0 or 'critical', got {args.friction}")
        try:
            options = variant_options(args.variant)
        except ValueError as error:
            raise UsageError(f"--variant: {error}") from None
        if args.steps is not None:
            options["steps"] = args.steps
        steps = options.setdefault("steps", DEFAULT_STEPS)
        if args.max_steps is not None:
            if options.get("score_every", DEFAULTS["score_every"]) == "adaptive":
                raise UsageError("--max-steps doubles a run of SPH steps: not with the default per-particle score "
                                 "hold (its --steps are evaluations); add --variant classic (or score_every=1)")
            if args.max_steps < steps:
                raise UsageError(f"--max-steps must be >= --steps ({steps}), got {args.max_steps}")
        if args.friction is not None:
            tokens = args.variant.strip().split("+")
            if "critical" in tokens or any(token.startswith("friction=") for token in tokens):
                raise UsageError(f"--friction {args.friction} and --variant {args.variant!r} both set the friction: "
                                 f"give one")
            options["friction"] = args.friction
        max_steps = args.max_steps
        sampler = ParVISampler(log_density=log_density, score=score, dim=dim, n=args.n, formulation=args.formulation,
                               eos=args.eos, alpha=args.alpha, c0=args.c0, h=args.support, max_steps=max_steps,
                               rule=args.rule, init_scale=args.init_scale, seed=args.seed,
                               progress=show_progress(args), **options)
        sampler.look_at_target()  # a score of the wrong sign or of another target: exit 2 before any work
        out = output_folder(args)
        out.mkdir(parents=True, exist_ok=True)
    summary = dict(target=args.target, score=args.score, variant=args.variant, steps_fixed=fixed, max_steps=max_steps,
                   **provenance(args, "sample"))
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", NotConvergedWarning)  # said once below, on the last line
            result = sampler.run()
    except ParVIDivergence as error:
        summary.update(converged=False, convergence_reason=str(error), parameters=_plain(sampler.parameters))
        (out / "summary.json").write_text(json.dumps(summary, indent=1))
        print(f"sphrelax sample: not converged: {error}; wrote {out}/summary.json", file=sys.stderr)
        return EXIT_NOT_CONVERGED
    except ValueError as error:  # the target misbehaved during the run (NaN, +inf, a wrong shape): the user's input
        raise UsageError(str(error)) from error
    x = result.samples
    np.save(out / "samples.npy", x)
    from ase import Atoms
    from ase.io import write

    positions = np.zeros((len(x), 3))
    positions[:, : min(dim, 3)] = x[:, : min(dim, 3)] if dim <= 3 else 0.0
    atoms = Atoms(f"H{len(x)}", positions=positions, pbc=False)
    atoms.new_array("sample", x)
    write(out / "samples.extxyz", atoms, format="extxyz")
    trace = {k: np.asarray(v).tolist() for k, v in result.trace.items()}
    info = _plain(result.info)
    costs = dict(n_density=result.n_density, n_score=result.n_score, wall_time=result.wall_time,
                 mean=x.mean(axis=0).tolist(), variance=x.var(axis=0).tolist())
    (out / "trace.json").write_text(json.dumps(dict(info=info, trace=trace, **costs), indent=1))
    converged = bool(result.info["converged"])
    verdict = info.get("verdict", {})
    summary.update(converged=converged, at_rest=verdict.get("at_rest"), check_passed=verdict.get("check_passed"),
                   verdict=verdict,
                   convergence_reason=result.info["convergence_reason"],
                   chosen_step=result.info["chosen_step"], parameters=info, **costs)
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    _plot(out / "samples.png", x, log_density)
    chosen = result.info["chosen_step"]
    state = "" if chosen == result.info["steps"] else f", the state of step {chosen} (--rule {args.rule})"
    print(f"{len(x)} samples in {dim}D after {result.info['steps']} steps{state} ({result.wall_time:.1f} s), "
          f"mean {np.array2string(x.mean(axis=0)[:4], precision=3)}; wrote {out}/samples.npy, samples.extxyz, "
          f"trace.json, summary.json, samples.png")
    if converged:
        return 0
    print(f"sphrelax sample: not converged: {result.info['convergence_reason']}"
          + ("" if not fixed else " (exit 0: --steps fixed the length)"), file=sys.stderr)
    return 0 if fixed else EXIT_NOT_CONVERGED


def _plain(info):
    """JSON-ready copy of a result's info: numbers, strings, lists and dicts of them kept, the rest as text."""
    import numpy as np

    def plain(v):
        if isinstance(v, np.generic):
            v = v.item()
        if isinstance(v, float) and not np.isfinite(v):
            return str(v)  # strict JSON has no inf or NaN
        if isinstance(v, (int, float, str, bool, type(None))):
            return v
        if isinstance(v, (list, tuple, np.ndarray)):
            return [plain(u) for u in np.asarray(v, dtype=object).tolist()] if isinstance(v, np.ndarray) else [
                plain(u) for u in v]
        if isinstance(v, dict):
            return {str(k): plain(u) for k, u in v.items()}
        return str(v)

    return {k: plain(v) for k, v in info.items()}

