"""SPH-ParVI on the 32-D logistic posterior: the diagnosis of the over-dispersion and the exact finish (issue 18).

Parts (each adds its key to ``<out>/results.json``; run them one at a time)::

    python reproductions/parvi-logistic-goal/run.py goal        # the remedy: knn+whiten+mala, M = 500 and 100, seeds 0-2
    python reproductions/parvi-logistic-goal/run.py gauss10d    # the same options on the 10-D Gaussian, M = 500, seed 0
    python reproductions/parvi-logistic-goal/run.py rest        # knn+whiten, M = 500, seed 0, 1000 and 3000 steps
    python reproductions/parvi-logistic-goal/run.py gauss32     # knn+whiten on N(NUTS mean, NUTS covariance), M = 500
    python reproductions/parvi-logistic-goal/run.py k           # knn+whiten, k = 5, 10, 40, M = 500, seed 0
    python reproductions/parvi-logistic-goal/run.py m           # knn+whiten, M = 100 and 2000, seed 0
    python reproductions/parvi-logistic-goal/run.py iid         # subsets of the NUTS reference of size M: the goal's noise
    python reproductions/parvi-logistic-goal/run.py spread      # the finish's step spread on the particles stranded in a tail

The diagnosis parts run the fluid alone (``knn+whiten``) and then, on its final particles and in its frozen
whitening frame, the two finishing kernels of ``ase_sphrelax/sampling/finish.py`` (``refill_radii``: exact radii
along the fluid's directions; ``mala_finish``: 200 MALA steps), and ``refill_radii`` on NUTS points in the same
frame (the same kernel, only the directions differ). ``goal`` and ``gauss10d`` call ``sample`` with
``finish="mala"`` (the fluid's particles before the finish are ``alternatives["fluid"]``).
"""
from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
from ase_sphrelax.checks import NotConvergedWarning  # noqa: E402
from ase_sphrelax.sampling import metrics  # noqa: E402
from ase_sphrelax.sampling.finish import mala_finish, refill_radii  # noqa: E402
from ase_sphrelax.sampling.sampler import ParVISampler, variant_options  # noqa: E402
from ase_sphrelax.sampling.targets import gaussian_target, get_target  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from lib.parvi_pinned import classic  # noqa: E402  (the sampler defaults the results were made with)
from lib.parvi_reference import logistic_reference  # noqa: E402
from lib.parvi_load import load  # noqa: E402

_highdim = load("parvi-highdim")
STARTED, _git_revision, _stamp, _update = _highdim.STARTED, _highdim._git_revision, _highdim._stamp, _highdim._update

OUT = Path(__file__).resolve().parent / "results"
#: the remedy's options: 540 fluid steps and 200 MALA steps, about 1000 evaluations (score + log-density) each
REMEDY = "knn+whiten+mala+finish_steps=200"
REMEDY_STEPS = 540


def goal_measures(x, ref):
    """The goal's measures against the NUTS reference (as ``../full_highdim/``): mean errors in posterior sds,
    sd ratios, the share within 10 %, energy distance; and the log-precision's (last coordinate) tail."""
    mean_c, sd_c = ref.mean(axis=0), ref.std(axis=0)
    z_c = np.abs(x.mean(axis=0) - mean_c) / sd_c
    q_c = x.std(axis=0) / sd_c
    return dict(mean_err_max=float(z_c.max()), mean_err_median=float(np.median(z_c)), worst_mean_coord=int(z_c.argmax()),
                sd_ratio_min=float(q_c.min()), sd_ratio_median=float(np.median(q_c)), sd_ratio_max=float(q_c.max()),
                worst_sd_coord=int(np.abs(q_c - 1).argmax()), sd_within_10pct=int(np.sum(np.abs(q_c - 1) <= 0.1)),
                goal_met=bool(z_c.max() <= 0.1 and np.all(np.abs(q_c - 1) <= 0.1)),
                energy=float(metrics.energy_distance(x, ref)),
                log_precision_sd_ratio=float(q_c[-1]), log_precision_mean_err=float(z_c[-1]),
                share_beyond_nuts_max=float(np.mean(x[:, -1] > ref[:, -1].max())))


def _fluid(target, m, seed, steps, **options):
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NotConvergedWarning)
        sampler = ParVISampler(target.log_density, target.score,
                               **classic(n=m, dim=target.dim, seed=seed, steps=steps, **options))
        res = sampler.run()
    kinetic = res.trace["kinetic"]
    return sampler, res, dict(wall=time.perf_counter() - t0, converged=bool(res.info["converged"]),
                              convergence_reason=res.info["convergence_reason"], n_score=res.n_score,
                              n_density=res.n_density, kinetic_final=float(kinetic[-1]),
                              kinetic_last_half_mean=float(np.mean(kinetic[len(kinetic) // 2:])))


def _finishes(target, sampler, x, ref, seed):
    """The two kernels of finish.py on the fluid's particles x in its frozen frame, and refill_radii on NUTS points
    in the same frame (the control: same kernel, the reference's directions)."""
    frame = (sampler.map.centre_c, sampler.map.l_cc)
    out = {}
    x_r, info_r = refill_radii(x, target.log_density, *frame, 3, np.random.default_rng([seed, 1]))
    out["radial"] = dict(goal_measures(x_r, ref), **info_r)
    nuts = ref[np.random.default_rng([seed, 2]).choice(len(ref), x.shape[0], replace=False)]
    n_r, info_n = refill_radii(nuts, target.log_density, *frame, 3, np.random.default_rng([seed, 3]))
    out["radial_on_nuts"] = dict(goal_measures(n_r, ref), **info_n)
    out["nuts_subset"] = goal_measures(nuts, ref)
    x_m, info_m = mala_finish(x, target.log_density, target.score, *frame, 200, np.random.default_rng([seed, 4]))
    out["mala200"] = dict(goal_measures(x_m, ref), **info_m)
    return out


def part_goal(args):
    target = get_target("logistic")
    ref = logistic_reference()
    rows = []
    for m in args.sizes:
        for seed in range(args.repeats):
            sampler, res, run = _fluid(target, m, seed, args.steps, **variant_options(args.variant))
            row = dict(m=m, seed=seed, variant=args.variant, steps=args.steps, **run,
                       evaluations_per_particle=(res.n_score + res.n_density) / m, finish=res.info["finish_info"],
                       fluid=goal_measures(res.alternatives["fluid"], ref), **goal_measures(res.samples, ref))
            print(json.dumps(row, default=float), flush=True)
            rows.append(row)
            _update(args.out, f"goal_{args.tag}", dict(rows=rows, **_stamp()))


def part_gauss10d(args):
    target = get_target("gaussian10d")
    ref = target.sample(5000, np.random.default_rng(12345))  # the protocol of ../highdim/ (parvi_highdim.py)
    rows = []
    for seed in range(args.repeats):
        iid = metrics.energy_distance(target.sample(500, np.random.default_rng(seed + 500)), ref)
        sampler, res, run = _fluid(target, 500, seed, args.steps, **variant_options(args.variant))
        e = metrics.energy_distance(res.samples, ref)
        e_fluid = metrics.energy_distance(res.alternatives["fluid"], ref)
        var_ratio = np.diag(np.cov(res.samples, rowvar=False)) / np.diag(target.cov)
        row = dict(m=500, seed=seed, variant=args.variant, steps=args.steps, **run, iid_energy=iid, energy=e,
                   ratio_to_iid=e / iid, fluid_energy=e_fluid, fluid_ratio_to_iid=e_fluid / iid,
                   var_ratio_min=float(var_ratio.min()), var_ratio_max=float(var_ratio.max()),
                   evaluations_per_particle=(res.n_score + res.n_density) / 500, finish=res.info["finish_info"])
        print(json.dumps(row, default=float), flush=True)
        rows.append(row)
        _update(args.out, f"gauss10d_{args.tag}", dict(rows=rows, **_stamp()))


def _diagnose(args, key, runs):
    """knn+whiten fluid runs ``(m, seed, steps, extra options)`` on the logistic posterior, with the finishes."""
    target = get_target("logistic")
    ref = logistic_reference()
    rows = []
    for m, seed, steps, extra in runs:
        sampler, res, run = _fluid(target, m, seed, steps, neighbours="knn", whiten="covariance", **extra)
        x = res.samples
        y = sampler.map.to_y(x)
        row = dict(m=m, seed=seed, steps=steps, options=extra, **run, **goal_measures(x, ref),
                   radius_in_frame=(float(np.linalg.norm(y, axis=1).mean()), float(np.linalg.norm(y, axis=1).std())),
                   virial=float(np.mean(np.einsum("pc,pc->p", x - x.mean(axis=0), target.score(x)))),
                   finishes=_finishes(target, sampler, x, ref, seed))
        print(json.dumps(row, default=float), flush=True)
        rows.append(row)
        _update(args.out, key, dict(rows=rows, **_stamp()))


def part_rest(args):
    _diagnose(args, "rest", [(500, 0, 1000, {}), (500, 0, 3000, {})])


def part_k(args):
    _diagnose(args, "k", [(500, 0, 1000, dict(k=k)) for k in (5, 10, 40)])


def part_m(args):
    _diagnose(args, "m", [(m, 0, 1000, {}) for m in args.sizes])


def part_gauss32(args):
    """knn+whiten on the Gaussian with the NUTS reference's mean and covariance: the shell without non-Gaussianity."""
    ref = logistic_reference()
    target = gaussian_target(ref.mean(axis=0), np.cov(ref, rowvar=False), name="gauss32")
    exact = target.sample(5000, np.random.default_rng(12345))
    rows = []
    for seed in range(args.repeats):
        iid = target.sample(500, np.random.default_rng(seed + 500))
        sampler, res, run = _fluid(target, 500, seed, args.steps, neighbours="knn", whiten="covariance")
        x = res.samples
        sd_c = np.sqrt(np.diag(target.cov))
        q_c = x.std(axis=0) / sd_c
        z_c = np.abs(x.mean(axis=0) - target.mean) / sd_c
        l_cc = np.linalg.cholesky(target.cov)
        radius_p = np.linalg.norm(np.linalg.solve(l_cc, (x - target.mean).T), axis=0)
        e, e_iid = metrics.energy_distance(x, exact), metrics.energy_distance(iid, exact)
        q_iid = iid.std(axis=0) / sd_c
        row = dict(m=500, seed=seed, steps=args.steps, **run, sd_ratio_min=float(q_c.min()),
                   sd_ratio_median=float(np.median(q_c)), sd_ratio_max=float(q_c.max()),
                   sd_within_10pct=int(np.sum(np.abs(q_c - 1) <= 0.1)), mean_err_max=float(z_c.max()),
                   mean_err_median=float(np.median(z_c)), radius_mean=float(radius_p.mean()),
                   radius_sd=float(radius_p.std()), iid_sd_ratio_min=float(q_iid.min()),
                   iid_sd_ratio_max=float(q_iid.max()), energy=e, iid_energy=e_iid, ratio_to_iid=e / e_iid)
        print(json.dumps(row, default=float), flush=True)
        rows.append(row)
        _update(args.out, "gauss32", dict(rows=rows, **_stamp()))


def part_iid(args):
    """The goal's measures for random subsets of size M of the 4000 NUTS draws (a stand-in for exact samples;
    without replacement, so slightly less noisy than i.i.d.)."""
    ref = logistic_reference()
    out = {}
    for m in (100, 500):
        rng = np.random.default_rng(m)
        rows = [goal_measures(ref[rng.choice(len(ref), m, replace=False)], ref) for _ in range(200)]
        out[str(m)] = dict(subsets=200, goal_met_share=float(np.mean([r["goal_met"] for r in rows])),
                           **{f"{name}_quantiles_10_50_90": np.quantile([r[name] for r in rows], [0.1, 0.5, 0.9]).tolist()
                              for name in ("mean_err_max", "mean_err_median", "sd_ratio_min", "sd_ratio_max",
                                           "sd_within_10pct", "energy")})
        print(m, json.dumps(out[str(m)], default=float), flush=True)
    _update(args.out, "iid", dict(out, **_stamp()))


def part_spread(args):
    """The finish's step spread on the stranded particles: one fluid (knn+whiten, M = 500, seed 0, 1000 steps), then
    mala_finish with a fixed step after the adaptation (spread 1) and with the spread 16, several lengths; and the
    NUTS reference's own numbers quoted in README.md (radius in its frame, |w|^2, the virial)."""
    target = get_target("logistic")
    ref = logistic_reference()
    sampler, res, run = _fluid(target, 500, 0, 1000, neighbours="knn", whiten="covariance")
    x = res.samples
    frame = (sampler.map.centre_c, sampler.map.l_cc)
    beyond = x[:, -1] > ref[:, -1].max()
    rows = [dict(kind="fluid", **run, **goal_measures(x, ref), stranded_log_precision=x[beyond, -1].tolist(),
                 log_precision_quantiles_1_50_99=np.quantile(x[:, -1], [0.01, 0.5, 0.99]).tolist())]
    for spread, steps in ((1.0, 200), (1.0, 1000), (16.0, 100), (16.0, 200), (16.0, 400)):
        x_m, info = mala_finish(x, target.log_density, target.score, *frame, steps, np.random.default_rng([0, 4]),
                                spread=spread)
        rows.append(dict(kind="mala", spread=spread, steps=steps, **info, **goal_measures(x_m, ref),
                         stranded_after=x_m[beyond, -1].tolist()))
        print(json.dumps(rows[-1], default=float), flush=True)
    c_c = ref.mean(axis=0)
    l_cc = np.linalg.cholesky(np.cov(ref, rowvar=False))
    radius = np.linalg.norm(np.linalg.solve(l_cc, (ref - c_c).T), axis=0)
    w2 = np.einsum("pc,pc->p", ref[:, :31], ref[:, :31])
    nuts = dict(radius_in_own_frame=(float(radius.mean()), float(radius.std())),
                w_squared_mean_sd=(float(w2.mean()), float(w2.std())),
                virial=float(np.mean(np.einsum("pc,pc->p", ref - c_c, target.score(ref)))),
                log_precision_quantiles_1_50_99=np.quantile(ref[:, -1], [0.01, 0.5, 0.99]).tolist(),
                log_precision_max=float(ref[:, -1].max()))
    print(json.dumps(nuts), flush=True)
    _update(args.out, "spread", dict(rows=rows, nuts=nuts, **_stamp()))


PARTS = dict(goal=part_goal, gauss10d=part_gauss10d, rest=part_rest, gauss32=part_gauss32, k=part_k, m=part_m,
             iid=part_iid, spread=part_spread)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("part", choices=sorted(PARTS))
    parser.add_argument("--sizes", type=int, nargs="+", default=[500, 100])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--steps", type=int, default=REMEDY_STEPS)
    parser.add_argument("--variant", default=REMEDY)
    parser.add_argument("--tag", default="main")
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    STARTED.update(git=_git_revision(), utc=time.strftime("%Y-%m-%d %H:%M:%S", time.gmtime()))
    PARTS[args.part](args)


if __name__ == "__main__":
    main()
