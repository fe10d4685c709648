"""SPH-ParVI against standard samplers: the evaluation of issue 8, item 5.

One command writes the report (tables, plots, JSON) under ``reproductions/parvi-baselines/results/`` (registry entry ``parvi-baselines``)::

    .venv/bin/python benchmarks/bench_sampling.py            # the full evaluation
    .venv/bin/python benchmarks/bench_sampling.py --quick    # M in {100, 500}, 2 repeats, 400 steps: .../quick/

The full run took about two hours on the 2-vCPU machine (SVGD at M = 2000 and SPH-ParVI in 10-D dominated; SVGD's
median heuristic is 2.5-5x cheaper per step since 2026-12-02, reproductions/parvi-banana-m2000/results/svgd_cost.json).

Methods, all started from the same initial points N(0, I) (seeded per repeat), all returning M points:

* ``iid`` — exact samples of the target (the floor; none for the logistic posterior);
* ``sph-default`` — SPH-ParVI's default (score force, isothermal, alpha = c0^2, adaptive h) and the default
  friction, which is now 1 / scale with the scale found from the target's score (1 on the unit targets; the
  banana, scale ~10 along x0, gets less). The tables published before 2026-12-02 used friction 1 (the default
  then): ``--sph-friction 1`` reproduces them (the label in the JSON meta says which was used);
* ``sph-optimal`` — the same run, the paper's "optimal state" rule (the recorded step of largest mean density);
* ``sph-tait`` — score force with the Tait EOS (gamma 7, rho0 = the initial mean density);
* ``sph-plog`` / ``sph-pinv`` — Algorithm 1, external pressure -alpha log(p + eps) / 1/(alpha (p + eps)),
  isothermal (these three variants run on the 2D targets at M <= 500 only);
* ``sph-<variant>`` — the issue-18 variants named by ``--sph-variants`` (default: ``default tait plog pinv``,
  the methods above), e.g. ``--sph-variants default whiten local whiten+local+critical``: each name is
  :func:`ase_sphrelax.sampling.sampler.variant_options` (tokens ``whiten``, ``local``, ``critical``,
  ``name=number``, joined by ``+``) and appears as its own method ``sph-<name>`` in report.md and results.json
  (a variant with ``score_every=K`` runs K times the SPH steps: the same score evaluations per particle);
* ``svgd`` — RBF kernel with the median heuristic times a factor, Adam, numpy, checked against blackjax;
* ``ula``, ``mala`` — M parallel chains, final states;
  SVGD's learning rate and bandwidth factor and ULA's and MALA's step sizes are set per target by ONE rule
  (``--tuning pilot``, the default): :func:`ase_sphrelax.sampling.tuning.tune`, a pilot of the run's
  evaluations on 100 of the initial points over a half-decade log grid, scored by the kernel Stein
  discrepancy (score only, no reference samples), once per target and number of evaluations. ``--tuning
  table`` restores the earlier hand-set values (``STEP`` for ULA/MALA, MALA acceptance 0.4-0.9 at the bulk;
  SVGD lr 0.05, factor 1) with which the tables published before 2026-12-02 were made;
* ``emcee`` — M walkers (affine-invariant ensemble), final states.

Equal evaluations: every method gets ``steps`` evaluations of the score or density per particle (MALA,
which needs both per step, runs ``steps / 2`` steps). Equal wall time: each baseline after SPH-ParVI
default's wall time (same target, M and repeat): a slower one's recorded state at that time, a faster one run
again with its steps scaled by the ratio of the wall times (at most 20x, ``--wall-factor``) and the step sizes tuned
for the run's evaluations. M = 2000 runs
2 repeats (``--repeats-large``). Metrics against a reference
sample (20000 i.i.d. points, or a long NUTS run for the logistic posterior): energy distance, sliced
Wasserstein (200 directions), mean error, relative covariance error, and for the 8-Gaussian ring the
mode-weight error (total variation).
"""
from __future__ import annotations

import argparse
import json
import os
import shlex
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _provenance import git_version  # noqa: E402

from ase_sphrelax.sampling import baselines, get_target, metrics  # noqa: E402
from ase_sphrelax.sampling import tuning as tuning_rule  # noqa: E402
from ase_sphrelax.sampling.sampler import ParVIDivergence, ParVISampler, variant_options  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "reproductions" / "parvi-baselines" / "results"
TARGETS = ["gaussian", "correlated", "ring8", "banana", "donut", "funnel", "gaussian10d", "logistic"]
# Langevin step sizes (ULA and MALA), chosen per target for MALA acceptance in 0.4-0.9 at the bulk
STEP = dict(gaussian=0.2, correlated=0.04, ring8=0.02, banana=0.05, donut=0.02, funnel=0.05, gaussian10d=0.02,
            logistic=2e-4)
SPH_VARIANTS = {
    "sph-default": dict(),
    "sph-tait": dict(eos="tait"),
    "sph-plog": dict(formulation="pressure-log"),
    "sph-pinv": dict(formulation="pressure-inverse"),
}


VARIANTS_ONLY = ("sph-tait", "sph-plog", "sph-pinv")
DEFAULT_SPH_VARIANTS = ["default", "tait", "plog", "pinv"]
BASELINES = ["svgd", "ula", "mala", "emcee"]


def sph_methods(names):
    """``{"sph-<name>": ParVISampler options}`` for ``--sph-variants`` names: the paper's variants of
    :data:`SPH_VARIANTS` (``tait``, ``plog``, ``pinv``) or a :func:`variant_options` name."""
    out = {}
    for name in names:
        method = f"sph-{name}"
        out[method] = dict(SPH_VARIANTS[method]) if method in SPH_VARIANTS else variant_options(name)
    return out


def reference_samples(target, n, seed, out):
    if target.sample is not None:
        return target.sample(n, np.random.default_rng(10_000 + seed))
    path = out / f"reference_{target.name}.npy"
    for candidate in (path, OUT / path.name):  # one stored reference serves every output folder
        if candidate.exists():
            return np.load(candidate)
    x = nuts_reference(target, n)
    np.save(path, x)
    return x


def evaluation_points(ref, n=5000):
    """The reference points the distances are measured against: ``n`` of ``ref`` drawn with seed 1."""
    return ref[np.random.default_rng(1).choice(len(ref), min(len(ref), n), replace=False)]


def reference_points(target, out=OUT):
    """The run's reference sample: 20000 i.i.d. points (seed 10000), or the stored NUTS draws (4000)."""
    return reference_samples(target, 20000 if target.sample else 4000, 0, out)


def start_points(target, m, seed):
    """Every method's start: M points of N(0, I) drawn with the seed."""
    return np.random.default_rng(seed).standard_normal((m, target.dim))


def comparison_set(target, m, seed, out=OUT):
    """One (target, M, seed) cell of the evaluation, for the scripts that run SPH-ParVI alone against it.

    Returns the points the distances are measured against (:func:`evaluation_points` of
    :func:`reference_points`), the energy distance of M i.i.d. points drawn with ``seed + 500`` to them (None for
    a target without an i.i.d. sampler) and the starts (:func:`start_points`): the ``iid`` row and the start of
    :func:`run_methods`.
    """
    ref = evaluation_points(reference_points(target, out))
    iid = (metrics.energy_distance(target.sample(m, np.random.default_rng(seed + 500)), ref)
           if target.sample is not None else None)
    return ref, iid, start_points(target, m, seed)


def nuts_reference(target, n, chains=4, warmup=2000):
    """Long NUTS (blackjax, window adaptation), thinned to n points over 4 chains."""
    import blackjax
    import jax
    import jax.numpy as jnp

    jax.config.update("jax_enable_x64", True)
    xd, yd = jnp.asarray(target.extra["x"]), jnp.asarray(target.extra["y"])
    nw = xd.shape[1]

    def logp(theta):
        w, s = theta[:nw], theta[nw]
        z = (xd @ w) * yd
        return (-jnp.logaddexp(0.0, -z).sum() + 0.5 * nw * s - 0.5 * jnp.exp(s) * w @ w + s - 0.01 * jnp.exp(s))

    samples = []
    for c in range(chains):
        key = jax.random.PRNGKey(c)
        warm = blackjax.window_adaptation(blackjax.nuts, logp)
        (state, params), _ = warm.run(key, jnp.zeros(nw + 1), num_steps=warmup)
        kernel = jax.jit(blackjax.nuts(logp, **params).step)
        per_chain = n // chains
        thin = 5
        draws = []
        for i in range(per_chain * thin):
            key, sub = jax.random.split(key)
            state, _ = kernel(sub, state)
            if i % thin == 0:
                draws.append(np.asarray(state.position))
        samples.append(np.array(draws))
    jax.config.update("jax_enable_x64", False)
    return np.concatenate(samples)


def score_all(x, target, ref, ref_stats):
    row = dict(energy=metrics.energy_distance(x, ref), sliced_w=metrics.sliced_wasserstein(x, ref, seed=1),
               mean_err=metrics.mean_error(x, ref_stats["mean"]), cov_err=metrics.cov_error(x, ref_stats["cov"]))
    if target.modes is not None:
        row["mode_err"] = metrics.mode_weight_error(x, target.modes, target.mode_weights)
    row.update(marginal_errors(x, ref_stats))
    return row


def marginal_errors(x, ref_stats):
    """The logistic goal's measures per coordinate j, against the reference's mean mu_j and sd s_j:
    ``|mean_j(x) - mu_j| / s_j`` (worst and median over j) and the sd ratio ``sd_j(x) / s_j`` (smallest and
    largest), with the fraction of coordinates whose sd is within 10 %."""
    sd_ref = np.sqrt(np.diag(np.atleast_2d(ref_stats["cov"])))
    mean_sd = np.abs(x.mean(axis=0) - np.asarray(ref_stats["mean"], dtype=float)) / sd_ref
    ratio = x.std(axis=0, ddof=1) / sd_ref
    return dict(mean_err_sd_max=float(mean_sd.max()), mean_err_sd_median=float(np.median(mean_sd)),
                sd_ratio_min=float(ratio.min()), sd_ratio_max=float(ratio.max()),
                sd_within_10pct=float(np.mean(np.abs(ratio - 1.0) <= 0.1)))


def equal_wall(name, target, m, seed, steps, res, wall, sph_wall, max_factor=20.0):
    """The baseline's samples after SPH-ParVI default's wall time: a slower baseline's recorded state at
    that time; a faster one run again with its steps scaled by the wall-time ratio (at most ``max_factor``),
    with the step sizes tuned for ``steps`` (the run's evaluations; tuning again for every longer run would
    cost pilots of up to 20x the run's length per target and repeat)."""
    if wall >= sph_wall:
        if name == "emcee":
            return res.samples, steps
        k = max(int(np.searchsorted(res.trace["wall"], sph_wall, side="right")) - 1, 0)
        return res.trace["samples"][k], int(res.trace["step"][k])
    longer = int(min(steps * sph_wall / max(wall, 1e-9), max_factor * steps))
    if longer <= steps:
        return res.samples, steps
    more = run_methods(target, m, seed, longer, [name], tuned_for=steps).get(name, {})
    return (more["result"].samples, longer) if "result" in more else (res.samples, steps)


TUNED = {}  # (target name, steps, tuning) -> {method: tune() result}; filled by tuned_steps()


def tuned_steps(target, steps, tuning="pilot"):
    """{method: (value, bandwidth_factor)} for svgd, ula, mala: the pilot rule, or the earlier hand-set table."""
    if tuning == "table":
        return dict(svgd=(0.05, 1.0), ula=(STEP[target.name], 1.0), mala=(STEP[target.name], 1.0))
    key = (target.name, steps)
    if key not in TUNED:
        x0 = np.random.default_rng(0).standard_normal((100, target.dim))
        TUNED[key] = {m: tuning_rule.tune(m, target.score, x0, steps, log_density=target.log_density)
                      for m in ("svgd", "ula", "mala")}
    return {m: (r["value"], r["bandwidth_factor"]) for m, r in TUNED[key].items()}


RUN_OPTIONS = dict(tuning="pilot", sph_friction=None, sph=dict(SPH_VARIANTS))  # set by main() from the command line


def run_methods(target, m, seed, steps, methods, tuned_for=None):
    x0 = start_points(target, m, seed)
    tuned = tuned_steps(target, steps if tuned_for is None else tuned_for, RUN_OPTIONS["tuning"])
    out = {}
    rec = max(steps // 20, 1)
    for name in methods:
        if name in VARIANTS_ONLY and (m > 500 or target.dim > 2):
            continue  # the other SPH-ParVI variants: 2D targets, M <= 500 (they lose there already)
        t0 = time.perf_counter()
        try:
            if name == "iid":
                if target.sample is None:
                    continue
                res = baselines.SampleResult(target.sample(m, np.random.default_rng(seed + 500)))
            elif name.startswith("sph"):
                options = dict(friction=RUN_OPTIONS["sph_friction"])
                options.update(RUN_OPTIONS["sph"][name])  # a variant's own friction rule wins
                # steps = score evaluations per particle: score_every=K (the score held over K SPH steps) runs K x
                res = ParVISampler(target.log_density, target.score, dim=target.dim, n=m, x0=x0,
                                   steps=steps * options.get("score_every", 1), seed=seed, **options).run()
            elif name == "svgd":
                res = baselines.svgd(target.score, x0, steps, lr=tuned["svgd"][0], bandwidth_factor=tuned["svgd"][1],
                                     record_every=rec)
            elif name == "ula":
                res = baselines.ula(target.score, x0, steps, tuned["ula"][0], seed=seed, record_every=rec)
            elif name == "mala":
                res = baselines.mala(target.log_density, target.score, x0, steps // 2, tuned["mala"][0], seed=seed,
                                     record_every=max(rec // 2, 1))
            elif name == "emcee":
                if m < 2 * target.dim:
                    continue
                res = baselines.emcee_ensemble(target.log_density, x0, steps, seed=seed)
            else:
                raise KeyError(name)
        except ParVIDivergence as exc:
            out[name] = dict(error=str(exc).splitlines()[0][:200], wall=time.perf_counter() - t0)
            continue
        except ValueError as exc:  # refused before it started (e.g. the kernel default with M < 656 in 10-D)
            out[name] = dict(error=str(exc).splitlines()[0][:200], refused=True, wall=time.perf_counter() - t0)
            continue
        if not np.all(np.isfinite(res.samples)):
            out[name] = dict(error="non-finite samples", wall=time.perf_counter() - t0)
            continue
        out[name] = dict(result=res, wall=time.perf_counter() - t0)
        if name == "sph-default":  # the paper's "optimal state" (largest mean density) of the same run
            out["sph-optimal"] = dict(result=baselines.SampleResult(res.alternatives["optimal"],
                                                                    n_score=res.n_score, info=res.info),
                                      wall=out[name]["wall"])
    return out


def sph_wall_reference(runs):
    """(method, wall time) of the SPH-ParVI run the baselines' equal-wall-time column is measured against:
    sph-default, else (when it refused or failed) the first SPH-ParVI variant that ran; (None, None) if none."""
    ran = [n for n in runs if n.startswith("sph-") and n != "sph-optimal" and "result" in runs[n]]
    ran.sort(key=lambda n: n != "sph-default")
    if not ran:
        return None, None
    return ran[0], runs[ran[0]]["result"].wall_time


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="M in {100, 500}, 2 repeats, 400 steps")
    parser.add_argument("--targets", nargs="+", default=TARGETS)
    parser.add_argument("--sizes", nargs="+", type=int, default=None)
    parser.add_argument("--repeats", type=int, default=None)
    parser.add_argument("--repeats-large", type=int, default=2, help="repeats at M >= 2000 (default 2)")
    parser.add_argument("--first-seed", type=int, default=0,
                        help="the repeats use seeds first-seed, first-seed + 1, ... (default 0): a run in parts")
    parser.add_argument("--wall-factor", type=float, default=20.0,
                        help="equal wall time: a faster baseline runs at most this many times its steps")
    parser.add_argument("--steps", type=int, default=None)
    parser.add_argument("--tuning", choices=("pilot", "table"), default="pilot",
                        help="SVGD/ULA/MALA steps: the pilot-KSD rule (default) or the earlier hand-set table")
    parser.add_argument("--sph-friction", type=float, default=None,
                        help="SPH-ParVI friction (default: the sampler's, 1 / target scale; 1 reproduces the "
                             "tables published before 2026-12-02)")
    parser.add_argument("--sph-variants", nargs="*", default=DEFAULT_SPH_VARIANTS,
                        help="SPH-ParVI variants, each its own method sph-<name>: tait, plog, pinv (the paper's) or "
                             "a sampler variant (tokens default, whiten, local, critical, name=number joined by '+', "
                             "e.g. whiten+local+critical); default: default tait plog pinv; none (an empty list): "
                             "the baselines alone, without the equal-wall-time column")
    parser.add_argument("--baselines", nargs="*", choices=BASELINES, default=BASELINES,
                        help="the baseline samplers to run (default all: svgd ula mala emcee; SVGD, O(M^2), takes "
                             "~6 min per target at M = 2000 with 1000 evaluations here at load 8, pilots included; "
                             "~20 min per run before the median heuristic used pdist, 2026-12-02)")
    parser.add_argument("--out", type=Path, default=None, help="default reproductions/parvi-baselines/results (quick: .../quick)")
    args = parser.parse_args(argv)
    try:
        sph = sph_methods(args.sph_variants)
    except ValueError as error:
        parser.error(f"--sph-variants: {error}")
    RUN_OPTIONS.update(tuning=args.tuning, sph_friction=args.sph_friction, sph=sph)
    started, load_start = time.time(), os.getloadavg()
    git_at_start = git_version()  # the code that runs (a commit made while it runs must not relabel it)
    args.out = args.out or (OUT / "quick" if args.quick else OUT)
    sizes = args.sizes or ([100, 500] if args.quick else [100, 500, 2000])
    repeats = args.repeats or (2 if args.quick else 3)
    steps = args.steps or (400 if args.quick else 1000)
    methods = ["iid", *sph, *args.baselines]
    args.out.mkdir(parents=True, exist_ok=True)
    print(f"load average {os.getloadavg()}; sizes {sizes}, repeats {repeats}, steps {steps}", flush=True)
    rows = []
    examples = {}
    floors = {}
    done = []
    for tname in args.targets:
        try:
            target = get_target(tname)
        except ImportError as exc:
            print(f"skip {tname}: {exc}")
            continue
        ref = reference_points(target, args.out)
        ref_stats = dict(mean=ref.mean(axis=0) if target.mean is None else target.mean,
                         cov=np.cov(ref, rowvar=False) if target.cov is None else target.cov)
        ref_eval = evaluation_points(ref)
        if target.sample is None:  # no i.i.d. floor: the distance between the two halves of the reference
            half = len(ref) // 2
            floors[tname] = metrics.energy_distance(ref[:half], ref[half:])
        for m in sizes:
            for seed in range(args.first_seed, args.first_seed + (repeats if m < 2000 else
                                                                    min(repeats, args.repeats_large))):
                t0 = time.perf_counter()
                runs = run_methods(target, m, seed, steps, methods)
                wall_method, sph_wall = sph_wall_reference(runs)
                for name, run in runs.items():
                    row = dict(target=tname, m=m, seed=seed, method=name, wall=run["wall"])
                    if "error" in run:
                        row["error"] = run["error"]
                        if run.get("refused"):
                            row["refused"] = True
                        rows.append(row)
                        continue
                    res = run["result"]
                    row.update(score_all(res.samples, target, ref_eval, ref_stats))
                    row["evaluations"] = res.evaluations
                    if sph_wall is not None and name in ("svgd", "ula", "mala", "emcee"):
                        x_wall, steps_wall = equal_wall(name, target, m, seed, steps, res, run["wall"], sph_wall,
                                                        args.wall_factor)
                        row["energy_at_sph_wall"] = metrics.energy_distance(x_wall, ref_eval)
                        row["steps_at_sph_wall"] = steps_wall
                        row["sph_wall_method"] = wall_method
                    rows.append(row)
                    if seed == 0 and m == 500 and target.dim == 2:
                        examples.setdefault(tname, {})[name] = res.samples
                this = [r for r in rows if r["target"] == tname and r["m"] == m and r["seed"] == seed]
                iid_energy = next((r["energy"] for r in this if r["method"] == "iid" and "energy" in r), None)
                for r in this:  # the measure: energy distance over that of i.i.d. samples of the same size
                    if iid_energy and "energy" in r:
                        r["energy_over_iid"] = r["energy"] / iid_energy
                print(f"{tname:12s} M={m:5d} seed={seed} {time.perf_counter() - t0:7.1f} s "
                      + " ".join(f"{n}={r.get('energy', float('nan')):.2e}" for n, r in
                                 ((r["method"], r) for r in rows if r["target"] == tname and r["m"] == m
                                  and r["seed"] == seed)), flush=True)
        # after every target: the report so far (a long run can be read while it goes on)
        meta = dict(git=git_at_start, sizes=sizes, repeats=repeats, first_seed=args.first_seed, steps=steps, load_average=os.getloadavg(),
                    tuning=args.tuning, tuned={t: tuned_steps(get_target(t), steps, args.tuning)
                                               for t in done + [tname]},
                    tuning_ksd={f"{k[0]}/{k[1]}": {m: r["table"] for m, r in v.items()} for k, v in TUNED.items()},
                    sph_friction=args.sph_friction if args.sph_friction is not None else "1 / target scale",
                    sph_variants={k: {o: str(v) for o, v in opts.items()} for k, opts in sph.items()},
                    command="benchmarks/bench_sampling.py " + shlex.join(sys.argv[1:] if argv is None else argv),
                    load_average_start=load_start, wall_so_far=time.time() - started,
                    reference_floor=floors, targets_done=done + [tname])
        done.append(tname)
        (args.out / "results.json").write_text(json.dumps(dict(meta=meta, rows=rows), indent=1, default=float))
        write_report(rows, meta, args.out)
        plot_examples(examples, args.out)
        plot_scaling(rows, args.out)
    print(f"wrote {args.out}")


def _summary(rows, key):
    """{(target, m, method): (mean, std, n)} of a metric over repeats."""
    table = {}
    for row in rows:
        if key in row:
            table.setdefault((row["target"], row["m"], row["method"]), []).append(row[key])
    return {k: (float(np.mean(v)), float(np.std(v)), len(v)) for k, v in table.items()}


def _methods(rows):
    """The methods of ``rows`` in report order: iid, the SPH-ParVI variants as they appear, the baselines."""
    present = list(dict.fromkeys(r["method"] for r in rows))
    sph = [m for m in present if m.startswith("sph-")]
    return (["iid"] if "iid" in present else []) + sph + [m for m in BASELINES if m in present]


def write_report(rows, meta, out):
    methods = _methods(rows)
    command = meta.get("command", "benchmarks/bench_sampling.py")
    wall = meta.get("wall_so_far")
    lines = ["# SPH-ParVI evaluation", "",
             f"Generated by `{command}` (git {meta['git']}); sizes {meta['sizes']}, "
             f"{meta['repeats']} repeats (seeds {meta.get('first_seed', 0)}..{meta.get('first_seed', 0) + meta['repeats'] - 1}"
             f"; at M >= 2000 at most --repeats-large), {meta['steps']} evaluations per particle, "
             f"load average {meta.get('load_average_start', '?')} at the start, {meta['load_average']} at the last "
             f"write" + (f", {wall / 60:.1f} min wall time for the targets done ({', '.join(meta['targets_done'])})"
                         if wall is not None else "") + ".", "",
             "Entries: mean ± standard deviation over the repeats; `div` = the run diverged or left no finite "
             "samples, `refused` = the sampler refused the configuration before it started (the error is in "
             "results.json); `-` = not applicable.", ""]
    if meta.get("reference_floor"):
        lines += ["Targets without an i.i.d. sampler: energy distance between the two halves of the reference "
                  "(its own noise floor): " + ", ".join(f"{k} {v:.3g}" for k, v in meta["reference_floor"].items()),
                  ""]
    for key, title in (("energy_over_iid", "Energy distance relative to i.i.d. samples of the same size and seed "
                                           "(the issue's measure; mean of the per-seed ratios)"),
                       ("energy", "Energy distance to the reference (lower is better)"),
                       ("sliced_w", "Sliced Wasserstein-2 (200 directions)"),
                       ("cov_err", "Relative covariance error"), ("mean_err", "Mean error"),
                       ("mode_err", "Mode-weight error, 8-Gaussian ring (total variation)"),
                       ("mean_err_sd_max", "Worst coordinate's mean error in reference sds"),
                       ("mean_err_sd_median", "Median coordinate's mean error in reference sds"),
                       ("sd_ratio_min", "Smallest marginal sd ratio (sample / reference)"),
                       ("sd_ratio_max", "Largest marginal sd ratio (sample / reference)"),
                       ("sd_within_10pct", "Fraction of marginal sds within 10 % of the reference"),
                       ("energy_at_sph_wall", "Energy distance at SPH-ParVI's wall time (sph-default's, else "
                                              "the first SPH-ParVI variant that ran: `sph_wall_method` in "
                                              "results.json)"),
                       ("wall", "Wall time per run [s]")):
        summary = _summary(rows, key)
        if not summary:
            continue
        errors = {(r["target"], r["m"], r["method"]): "refused" if r.get("refused") else "div"
                  for r in rows if "error" in r}
        lines += [f"## {title}", "", "| target | M | " + " | ".join(methods) + " |",
                  "| --- | --- | " + " | ".join("---" for _ in methods) + " |"]
        for tname, m in sorted({(k[0], k[1]) for k in summary}, key=lambda t: (TARGETS.index(t[0]), t[1])):
            cells = []
            for meth in methods:
                if (tname, m, meth) in summary:
                    mu, sd, _ = summary[(tname, m, meth)]
                    cells.append(f"{mu:.3g} ± {sd:.1g}")
                else:
                    cells.append(errors.get((tname, m, meth), "-") if key != "wall" else "-")
            lines.append(f"| {tname} | {m} | " + " | ".join(cells) + " |")
        lines.append("")
    (out / "report.md").write_text("\n".join(lines))


def plot_examples(examples, out):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    for tname, by_method in examples.items():
        target = get_target(tname)
        names = list(by_method)
        fig, axes = plt.subplots(1, len(names), figsize=(2.6 * len(names), 2.8), squeeze=False)
        allx = np.concatenate([v for v in by_method.values()])
        lo, hi = np.percentile(allx, 0.5, axis=0), np.percentile(allx, 99.5, axis=0)
        pad = 0.1 * (hi - lo)
        gx, gy = np.meshgrid(np.linspace(lo[0] - pad[0], hi[0] + pad[0], 200),
                             np.linspace(lo[1] - pad[1], hi[1] + pad[1], 200))
        lp = target.log_density(np.stack([gx.ravel(), gy.ravel()], 1)).reshape(gx.shape)
        for ax, name in zip(axes[0], names):
            ax.contour(gx, gy, np.exp(lp - lp.max()), levels=6, colors="0.6", linewidths=0.6)
            ax.scatter(*by_method[name].T, s=2, color="C3")
            ax.set_title(name, fontsize=8)
            ax.set_xticks([])
            ax.set_yticks([])
        fig.suptitle(f"{tname}, M = 500, seed 0", fontsize=9)
        fig.tight_layout()
        fig.savefig(out / f"samples_{tname}.png", dpi=110)
        plt.close(fig)


def plot_scaling(rows, out):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    summary = _summary(rows, "energy")
    targets = [t for t in TARGETS if any(k[0] == t for k in summary)]
    fig, axes = plt.subplots(2, (len(targets) + 1) // 2, figsize=(3.2 * ((len(targets) + 1) // 2), 6), squeeze=False)
    for ax, tname in zip(axes.ravel(), targets):
        for i, meth in enumerate(m for m in _methods(rows) if m not in ("sph-optimal", "sph-plog", "sph-pinv")):
            pts = sorted((k[1], v) for k, v in summary.items() if k[0] == tname and k[2] == meth)
            if pts:
                ax.errorbar([p[0] for p in pts], [p[1][0] for p in pts], yerr=[p[1][1] for p in pts], label=meth,
                            marker="o", ms=3, color=f"C{i}")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_title(tname, fontsize=9)
        ax.set_xlabel("M")
    axes[0, 0].set_ylabel("energy distance")
    axes[0, 0].legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(out / "energy_distance_vs_m.png", dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    main()
