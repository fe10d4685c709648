"""SPH-ParVI above 3 dimensions: the k-nearest-neighbour variant (``neighbours="knn"``, issue 18 item 3).

Parts (each writes/updates ``<out>/results.json``; run them one at a time):

* ``stationary``: the resting state on a unit Gaussian in 1D (M = 300), 2D (M = 500) and 10-D (M = 500):
  variance per axis, kurtosis of a coordinate, and the virial identity of theory.py eq. K5
  (``mean |x|^2 = d`` at rest), against the kernel default where it runs;
* ``gaussian10d``: the 10-D Gaussian (condition number 100) at M = 100, 500 (2000 with ``--sizes``), 1000
  evaluations per particle: energy distance to 5000 i.i.d. reference points, relative to i.i.d. samples of
  the same size (as ``benchmarks/bench_sampling.py``);
* ``logistic``: the 32-D logistic posterior at M = 100, 500: posterior mean error in posterior sds and the
  marginal sd ratios against the NUTS reference (``reproductions/lib/parvi_reference.py``);
* ``timing``: the neighbour search (cKDTree query of k + 1) against brute force in 32-D and 10-D;
* ``probes``: the whitening map at M = 100, a 2000-step logistic run, the 32-D shell, knn-ratio's pairing;
* ``renewals``: the controlled experiment of the bounded whitening renewal (whitening.py, theory.py eq. W4):
  ``knn+whiten`` at M = 100 in 10-D with unbounded and bounded renewals, the particles' covariance in the
  fluid's coordinates at every renewal, and the energy distance;
* ``renewals2d``: the bounded renewal on the 2D targets (``whiten+local+critical`` from standard-normal starting
  points, as ``benchmarks/bench_sampling.py`` runs it): energy distance relative to i.i.d., unbounded and bounded;
* ``ratio_weights``: why ``knn-ratio`` diverges on the logistic posterior and not on the 10-D Gaussian: the
  spread of ``log p`` over each particle's ball and the score weights ``W_b`` (eq. R3) along the run;
* ``tables``: the markdown tables of ``results.json`` (written to ``tables.md``).

Usage::

    PYTHONPATH=$PWD python reproductions/parvi-highdim/run.py stationary
    PYTHONPATH=$PWD python reproductions/parvi-highdim/run.py gaussian10d --sizes 100 500
    PYTHONPATH=$PWD python reproductions/parvi-highdim/run.py logistic --sizes 100 500
    PYTHONPATH=$PWD python reproductions/parvi-highdim/run.py timing
"""
from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import time
import warnings
from pathlib import Path

import numpy as np

import sys

from ase_sphrelax.checks import NotConvergedWarning
from ase_sphrelax.sampling import metrics
from ase_sphrelax.sampling.sampler import ParVIDivergence, ParVISampler
from ase_sphrelax.sampling.targets import gaussian_target, get_target

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from lib.parvi_pinned import classic  # noqa: E402  (the sampler defaults the results were made with)
from lib.parvi_reference import logistic_reference  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
OUT = Path(__file__).resolve().parent / "results"

#: the configurations compared: the variant alone and with the whitening of item 1
CONFIGS = {"knn": dict(neighbours="knn"), "knn+whiten": dict(neighbours="knn", whiten="covariance"),
           "knn+whiten(20,0.8)": dict(neighbours="knn", whiten="covariance", whiten_every=20, whiten_until=0.8),
           "knn+whiten+local": dict(neighbours="knn", whiten="covariance", time_step="local"),
           "knn-ratio+whiten": dict(neighbours="knn-ratio", whiten="covariance"),
           "knn-ratio+whiten+local": dict(neighbours="knn-ratio", whiten="covariance", time_step="local"),
           "knn-ratio+whiten(c0.15)": dict(neighbours="knn-ratio", whiten="covariance", courant=0.15)}


def _git_revision():
    try:
        return subprocess.run(["git", "describe", "--always", "--dirty"], cwd=ROOT, capture_output=True,
                              text=True).stdout.strip()
    except OSError:
        return "?"


#: the revision when this process started (the code it runs), set by main()
STARTED = {}


def _stamp():
    """The revision the part ran (at its start), and the load and UTC time when it finished."""
    return dict(git=STARTED.get("git") or _git_revision(), started_utc=STARTED.get("utc"), load=os.getloadavg(),
                utc=time.strftime("%Y-%m-%d %H:%M:%S", time.gmtime()))


def _update(out, key, value):
    path = out / "results.json"
    data = json.loads(path.read_text()) if path.exists() else {}
    data[key] = value
    path.write_text(json.dumps(data, indent=1, default=float) + "\n")


def _run(target, m, seed, steps, **kwargs):
    """sample() with the warnings caught: (result or None, error, converged, wall)."""
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NotConvergedWarning)
        try:
            sampler = ParVISampler(target.log_density, target.score,
                                   **classic(n=m, dim=target.dim, seed=seed, steps=steps, **kwargs))
            res = sampler.run()
        except (ParVIDivergence, ValueError) as exc:
            return None, str(exc).splitlines()[0][:300], False, time.perf_counter() - t0
    search = getattr(sampler.model, "search", None)
    if search is not None:  # the neighbour search: tree rebuilds against evaluations
        res.info["search_rebuilds"], res.info["search_calls"] = search.rebuilds, search.calls
    return res, None, bool(res.info["converged"]), time.perf_counter() - t0


def _iid_radius_sd(d):
    """Standard deviation of |x| for x ~ N(0, I_d) (a chi variable)."""
    mean = math.sqrt(2.0) * math.exp(math.lgamma((d + 1) / 2) - math.lgamma(d / 2))
    return math.sqrt(d - mean**2)


def part_stationary(args):
    rows = []
    for d, m in ((1, 300), (2, 500), (10, 500)):
        target = gaussian_target(np.zeros(d), np.eye(d), name=f"unit{d}")
        for name, kw in (("knn", dict(neighbours="knn")), ("knn, k=8", dict(neighbours="knn", k=8)),
                         ("knn-ratio", dict(neighbours="knn-ratio")),
                         ("knn-ratio, local steps", dict(neighbours="knn-ratio", time_step="local")),
                         ("kernel default", {})):
            for steps in args.stationary_steps:
                res, err, conv, wall = _run(target, m, 0, steps, **kw)
                row = dict(d=d, m=m, config=name, steps=steps, wall=wall, error=err)
                if res is not None:
                    x = res.samples
                    var_c = x.var(axis=0)
                    kurt_c = (x**4).mean(axis=0) / (x**2).mean(axis=0) ** 2
                    radius_p = np.sqrt((x**2).sum(axis=1))
                    row.update(radius_sd=float(radius_p.std()), iid_radius_sd=_iid_radius_sd(d),
                               var_mean=float(var_c.mean()), var_min=float(var_c.min()), var_max=float(var_c.max()),
                               mean_sq_radius_over_d=float((x**2).sum(axis=1).mean() / d),
                               mean_abs=float(np.abs(x.mean(axis=0)).max()), kurtosis=float(kurt_c.mean()),
                               kinetic_final=float(res.trace["kinetic"][-1]), converged=conv,
                               steps_run=int(res.info["steps"]))
                print(json.dumps(row, default=float), flush=True)
                rows.append(row)
    _update(args.out, "stationary", dict(rows=rows, **_stamp()))


def part_gaussian10d(args):
    target = get_target("gaussian10d")
    ref = target.sample(5000, np.random.default_rng(12345))
    rows = []
    for m in args.sizes:
        for seed in range(args.first_seed, args.first_seed + args.repeats):
            iid = metrics.energy_distance(target.sample(m, np.random.default_rng(seed + 500)), ref)
            for name in args.configs:
                res, err, conv, wall = _run(target, m, seed, args.steps, **CONFIGS[name])
                row = dict(m=m, seed=seed, config=name, steps=args.steps, iid_energy=iid, wall=wall, error=err)
                if res is not None:
                    e = metrics.energy_distance(res.samples, ref)
                    var_ratio = np.diag(np.cov(res.samples, rowvar=False)) / np.diag(target.cov)
                    row.update(energy=e, ratio_to_iid=e / iid, converged=conv,
                               search_rebuilds=res.info.get("search_rebuilds"),
                               search_calls=res.info.get("search_calls"), n_score=res.n_score, n_density=res.n_density,
                               cov_err=metrics.cov_error(res.samples, target.cov),
                               var_ratio_min=float(var_ratio.min()), var_ratio_max=float(var_ratio.max()),
                               mahalanobis_sq_over_d=float(np.mean(np.einsum(
                                   "pc,cd,pd->p", res.samples, np.linalg.inv(target.cov), res.samples)) / 10))
                print(json.dumps(row, default=float), flush=True)
                rows.append(row)
                _update(args.out, f"gaussian10d_{args.tag}", dict(rows=rows, **_stamp()))


def part_logistic(args):
    target = get_target("logistic")
    ref = logistic_reference()
    mean_c, sd_c = ref.mean(axis=0), ref.std(axis=0)
    rows = []
    for m in args.sizes:
        for seed in range(args.repeats):
            for name in args.configs:
                res, err, conv, wall = _run(target, m, seed, args.steps, **CONFIGS[name])
                row = dict(m=m, seed=seed, config=name, steps=args.steps, wall=wall, error=err)
                if res is not None:
                    x = res.samples
                    z_c = np.abs(x.mean(axis=0) - mean_c) / sd_c
                    ratio_c = x.std(axis=0) / sd_c
                    row.update(mean_err_sd_max=float(z_c.max()), mean_err_sd_median=float(np.median(z_c)),
                               sd_ratio_min=float(ratio_c.min()), sd_ratio_max=float(ratio_c.max()),
                               sd_ratio_median=float(np.median(ratio_c)),
                               sd_within_10pct=int(np.sum(np.abs(ratio_c - 1) <= 0.1)),
                               energy=metrics.energy_distance(x, ref), converged=conv, n_score=res.n_score,
                               kinetic_final=float(res.trace["kinetic"][-1]),
                               kinetic_last_half_mean=float(np.mean(res.trace["kinetic"][len(res.trace["kinetic"]) // 2:])),
                               search_rebuilds=res.info.get("search_rebuilds"),
                               search_calls=res.info.get("search_calls"),
                               n_density=res.n_density)
                print(json.dumps(row, default=float), flush=True)
                rows.append(row)
                _update(args.out, f"logistic_{args.tag}", dict(rows=rows, reference_halves_energy=float(
                    metrics.energy_distance(ref[: len(ref) // 2], ref[len(ref) // 2:])), **_stamp()))


def part_timing(args):
    from scipy.spatial import cKDTree
    from scipy.spatial.distance import cdist

    rows = []
    for d in (10, 32):
        for m in (500, 2000):
            x = np.random.default_rng(0).standard_normal((m, d))
            k = 20
            for rnd in range(3):
                t0 = time.perf_counter()
                cKDTree(x).query(x, k=k + 1)
                tree = time.perf_counter() - t0
                t0 = time.perf_counter()
                dist = cdist(x, x)
                np.argpartition(dist, k, axis=1)[:, : k + 1]
                brute = time.perf_counter() - t0
                rows.append(dict(d=d, m=m, k=k, round=rnd, tree=tree, brute=brute))
    for row in rows:
        print(row)
    med = {}
    for d in (10, 32):
        for m in (500, 2000):
            sel = [r for r in rows if r["d"] == d and r["m"] == m]
            med[f"d{d}_m{m}"] = dict(tree=float(np.median([r["tree"] for r in sel])),
                                     brute=float(np.median([r["brute"] for r in sel])))
    print(med)
    _update(args.out, "timing", dict(rows=rows, median=med, **_stamp()))


def part_probes(args):
    """The numbers the README and theory.py quote besides the tables: the whitening map of ``knn+whiten`` at M = 100
    (default start against i.i.d. starting points), a 2000-step logistic run, the 32-D unit Gaussian's shell, and
    the pairing of ``knn-ratio`` without its shape term (eq. R5)."""
    from scipy.spatial import cKDTree

    import ase_sphrelax.models.parvi_knn as parvi_knn
    from ase_sphrelax.sampling import whitening

    out = {}
    target = get_target("gaussian10d")
    renew = whitening.AffineMap.renew
    for start in ("default", "iid"):
        eig = []

        def recording(self, y_pc, v_pc, rho_p=None):
            result = renew(self, y_pc, v_pc, rho_p)
            eig.append(np.linalg.eigvalsh(self.l_cc @ self.l_cc.T).tolist())
            return result

        whitening.AffineMap.renew = recording
        try:
            x0 = None if start == "default" else target.sample(100, np.random.default_rng(5))
            res, err, conv, wall = _run(target, 100, 0, args.steps, x0=x0, **CONFIGS["knn+whiten"])
        finally:
            whitening.AffineMap.renew = renew
        out[f"gaussian10d_m100_knn+whiten_start_{start}"] = dict(
            map_eigenvalues_min=[min(e) for e in eig], map_eigenvalues_max=[max(e) for e in eig],
            target_eigenvalues=np.linalg.eigvalsh(target.cov).tolist(), error=err)
        print(start, [f"{min(e):.3g}-{max(e):.3g}" for e in eig], flush=True)
    logistic = get_target("logistic")
    ref = logistic_reference()
    res, err, conv, wall = _run(logistic, 500, 0, 2000, **CONFIGS["knn+whiten(20,0.8)"])
    ratio_c = res.samples.std(axis=0) / ref.std(axis=0)
    out["logistic_m500_knn+whiten(20,0.8)_2000_steps"] = dict(
        sd_ratio_min=float(ratio_c.min()), sd_ratio_median=float(np.median(ratio_c)), sd_ratio_max=float(ratio_c.max()),
        mean_err_sd_max=float(np.max(np.abs(res.samples.mean(axis=0) - ref.mean(axis=0)) / ref.std(axis=0))),
        reference_virial=float(np.mean(np.einsum("pc,pc->p", ref - ref.mean(axis=0), logistic.score(ref)))),
        samples_virial=float(np.mean(np.einsum("pc,pc->p", res.samples - res.samples.mean(axis=0),
                                                logistic.score(res.samples)))), wall=wall)
    print(out["logistic_m500_knn+whiten(20,0.8)_2000_steps"], flush=True)
    unit32 = gaussian_target(np.zeros(32), np.eye(32), name="unit32")
    res, err, conv, wall = _run(unit32, 500, 0, args.steps, neighbours="knn")
    x = res.samples
    out["unit32_m500_knn"] = dict(radius_sd=float(np.sqrt((x**2).sum(axis=1)).std()), iid_radius_sd=_iid_radius_sd(32),
                                  var_min=float(x.var(axis=0).min()), var_max=float(x.var(axis=0).max()),
                                  mean_sq_radius_over_d=float((x**2).sum(axis=1).mean() / 32), wall=wall)
    print(out["unit32_m500_knn"], flush=True)
    unit10 = gaussian_target(np.zeros(10), np.eye(10), name="unit10")
    iid = unit10.sample(500, np.random.default_rng(1))
    near_iid = cKDTree(iid).query(iid, 2)[0][:, 1]
    for shape in (0.0, parvi_knn.DEFAULT_SHAPE):
        saved, parvi_knn.DEFAULT_SHAPE = parvi_knn.DEFAULT_SHAPE, shape
        try:
            res, err, conv, wall = _run(unit10, 500, 0, 600, neighbours="knn-ratio")
        finally:
            parvi_knn.DEFAULT_SHAPE = saved
        near = cKDTree(res.samples).query(res.samples, 2)[0][:, 1]
        out[f"unit10_m500_knn-ratio_shape{shape}_600_steps"] = dict(
            nearest_q10=float(np.quantile(near, 0.1)), nearest_median=float(np.median(near)),
            iid_nearest_q10=float(np.quantile(near_iid, 0.1)), iid_nearest_median=float(np.median(near_iid)))
        print(shape, out[f"unit10_m500_knn-ratio_shape{shape}_600_steps"], flush=True)
    _update(args.out, "probes", dict(out, **_stamp()))


def part_renewals(args):
    """``knn+whiten`` on the 10-D Gaussian with the renewal unbounded (``RENEWAL_MAX_SHRINK = None``, the map of
    the moment) and bounded (the default): at each renewal the extreme eigenvalues of the particles' covariance in
    the fluid's coordinates before it (1 for a fluid that has not moved away from the map) and of the renewed map's
    covariance ``L L^T`` (the target's: 0.1-10), the kinetic energy per particle; the final energy distance."""
    from ase_sphrelax.sampling import whitening

    target = get_target("gaussian10d")
    ref = target.sample(5000, np.random.default_rng(12345))
    renew, bound = whitening.AffineMap.renew, whitening.RENEWAL_MAX_SHRINK
    rows = []
    for m in args.sizes:
        for seed in range(args.repeats):
            iid = metrics.energy_distance(target.sample(m, np.random.default_rng(seed + 500)), ref)
            for label, max_shrink in (("unbounded", None), ("bounded", bound)):
                log = []

                def recording(self, y_pc, v_pc, rho_p=None):
                    cov_y = np.linalg.eigvalsh(np.atleast_2d(np.cov(y_pc, rowvar=False)))
                    result = renew(self, y_pc, v_pc, rho_p)
                    map_eig = np.linalg.eigvalsh(self.l_cc @ self.l_cc.T)
                    log.append([float(cov_y.min()), float(cov_y.max()), float(map_eig.min()), float(map_eig.max()),
                                0.5 * float(np.einsum("pc,pc->", v_pc, v_pc)) / len(v_pc)])
                    return result

                whitening.AffineMap.renew, whitening.RENEWAL_MAX_SHRINK = recording, max_shrink
                try:
                    res, err, conv, wall = _run(target, m, seed, args.steps, **CONFIGS["knn+whiten"])
                finally:
                    whitening.AffineMap.renew, whitening.RENEWAL_MAX_SHRINK = renew, bound
                row = dict(m=m, seed=seed, renewal=label, max_shrink=max_shrink, iid_energy=iid, wall=wall,
                           error=err, renewals=log)
                if res is not None:
                    e = metrics.energy_distance(res.samples, ref)
                    var_ratio = np.diag(np.cov(res.samples, rowvar=False)) / np.diag(target.cov)
                    row.update(energy=e, ratio_to_iid=e / iid, var_ratio_min=float(var_ratio.min()),
                               var_ratio_max=float(var_ratio.max()))
                print(json.dumps({k: v for k, v in row.items() if k != "renewals"}, default=float), flush=True)
                print("  renewals (cov_y min, max, map min, max, kinetic):",
                      [" ".join(f"{a:.2g}" for a in entry) for entry in log], flush=True)
                rows.append(row)
                _update(args.out, f"renewals_{args.tag}", dict(rows=rows, **_stamp()))


def part_renewals2d(args):
    from ase_sphrelax.sampling import whitening
    from ase_sphrelax.sampling.sampler import variant_options

    bound = whitening.RENEWAL_MAX_SHRINK
    rows = []
    for m in args.sizes:
        for name in ("gaussian", "correlated", "ring8", "banana", "donut", "funnel"):
            target = get_target(name)
            ref = target.sample(5000, np.random.default_rng(12345))
            iid = metrics.energy_distance(target.sample(m, np.random.default_rng(500)), ref)
            row = dict(target=name, m=m, steps=args.steps, iid_energy=iid)
            for label, max_shrink in (("unbounded", None), ("bounded", bound)):
                whitening.RENEWAL_MAX_SHRINK = max_shrink
                try:
                    res, err, conv, wall = _run(target, m, 0, args.steps,
                                                x0=np.random.default_rng(0).standard_normal((m, 2)),
                                                **variant_options("whiten+local+critical"))
                finally:
                    whitening.RENEWAL_MAX_SHRINK = bound
                row[label] = err if res is None else metrics.energy_distance(res.samples, ref) / iid
            print(json.dumps(row, default=float), flush=True)
            rows.append(row)
            _update(args.out, f"renewals2d_{args.tag}", dict(rows=rows, **_stamp()))


def part_ratio_weights(args):
    """``knn-ratio+whiten+local`` at M = 100 on the 10-D Gaussian and the 32-D logistic posterior: every 50
    evaluations, the spread ``max_b log p(x_b) - min_b log p(x_b)`` over ``{a} + N_k(a)`` (median and max over a;
    the importance weights ``q_b = p(x_b)^-1`` vary by its exponential), the score weights ``W_b`` of eq. R3 (the
    largest, and the fraction of particles below 0.1, which hardly feel their own score), the standard deviation of
    ``log p`` over the particles and the kinetic energy per particle."""
    import ase_sphrelax.models.parvi_knn as parvi_knn

    evaluate = parvi_knn.KNNRatioParVIModel.evaluate
    out = {}
    for name in ("gaussian10d", "logistic"):
        target = get_target(name)
        log = []

        def recording(self, r_pc, v_pc=None, rho_p=None, want_energy=False):
            ev = evaluate(self, r_pc, v_pc, rho_p, want_energy)
            self.n_calls = getattr(self, "n_calls", 0) + 1
            if self.n_calls % 50 == 1:
                idx_pk, _ = parvi_knn.knn_graph(np.asarray(r_pc), self.k)
                ball_pk = np.concatenate([ev.log_p[:, None], ev.log_p[idx_pk]], axis=1)
                spread_p = ball_pk.max(axis=1) - ball_pk.min(axis=1)
                kinetic = None if v_pc is None else 0.5 * float(np.einsum("pc,pc->", v_pc, v_pc)) / len(v_pc)
                log.append(dict(evaluation=self.n_calls, ball_spread_median=float(np.median(spread_p)),
                                ball_spread_max=float(spread_p.max()), weight_max=float(ev.weight.max()),
                                weight_below_0p1=float(np.mean(ev.weight < 0.1)),
                                log_p_sd=float(np.std(ev.log_p)), kinetic=kinetic))
            return ev

        parvi_knn.KNNRatioParVIModel.evaluate = recording
        try:
            res, err, conv, wall = _run(target, 100, 0, args.steps, **CONFIGS["knn-ratio+whiten+local"])
        finally:
            parvi_knn.KNNRatioParVIModel.evaluate = evaluate
        out[name] = dict(error=err, wall=wall, log=log)
        print(name, err, flush=True)
        for entry in log:
            print("  ", json.dumps(entry, default=float), flush=True)
    _update(args.out, "ratio_weights", dict(out, **_stamp()))


def _table(lines, title, columns, rows, lead, cells):
    """Append a markdown table: the ``lead`` keys of each row, then ``cells(row)`` or the row's error."""
    lines += ([title, ""] if title else []) + ["| " + " | ".join(columns) + " |", "|" + " --- |" * len(columns)]
    for r in rows:
        body = ([f"error: {r['error'][:90]}"] + [""] * (len(columns) - len(lead) - 1)) if r.get("error") else cells(r)
        lines.append("| " + " | ".join([str(r[c]) for c in lead] + body) + " |")
    lines.append("")


def _stamp_line(key, entry):
    return f"`{key}` ({entry['utc']} UTC, git {entry['git']}, load {entry['load'][0]:.1f})"


def part_tables(args):
    """Markdown tables of every part in results.json (printed; the README quotes them)."""
    data = json.loads((args.out / "results.json").read_text())
    lines = []
    if "stationary" in data:
        _table(lines, _stamp_line("stationary", data["stationary"]),
               ["d", "M", "configuration", "steps", "var per axis (mean, min-max)", "mean sq radius / d", "kurtosis",
                "radius sd (i.i.d.)", "final kinetic", "max abs mean"], data["stationary"]["rows"],
               ["d", "m", "config", "steps"],
               lambda r: [f"{r['var_mean']:.4f} ({r['var_min']:.3f}-{r['var_max']:.3f})",
                          f"{r['mean_sq_radius_over_d']:.4f}", f"{r['kurtosis']:.3f}",
                          f"{r['radius_sd']:.3f} ({r['iid_radius_sd']:.3f})", f"{r['kinetic_final']:.2g}",
                          f"{r['mean_abs']:.2g}"])
    for key in sorted(k for k in data if k.startswith("gaussian10d")):
        _table(lines, _stamp_line(key, data[key]),
               ["M", "seed", "configuration", "energy distance", "i.i.d.", "ratio to i.i.d.",
                "var ratio min-max (per x axis)", "Mahalanobis^2 / d", "tree rebuilds / evaluations", "wall s"],
               data[key]["rows"], ["m", "seed", "config"],
               lambda r: [f"{r['energy']:.4g}", f"{r['iid_energy']:.4g}", f"**{r['ratio_to_iid']:.2f}**",
                          f"{r['var_ratio_min']:.2f}-{r['var_ratio_max']:.2f}", f"{r['mahalanobis_sq_over_d']:.3f}",
                          f"{r['search_rebuilds']} / {r['search_calls']}", f"{r['wall']:.0f}"])
    for key in sorted(k for k in data if k.startswith("logistic")):
        _table(lines, _stamp_line(key, data[key]) + f"; the reference's two halves are "
               f"{data[key]['reference_halves_energy']:.3g} apart in energy distance",
               ["M", "configuration", "mean error / sd (max, median)", "sd ratio (min, median, max)",
                "sds within 10 % (of 32)", "energy distance", "wall s"], data[key]["rows"], ["m", "config"],
               lambda r: [f"{r['mean_err_sd_max']:.2f}, {r['mean_err_sd_median']:.3f}",
                          f"{r['sd_ratio_min']:.2f}, {r['sd_ratio_median']:.2f}, {r['sd_ratio_max']:.2f}",
                          str(r["sd_within_10pct"]), f"{r['energy']:.3g}", f"{r['wall']:.0f}"])
    for key in sorted(k for k in data if k.startswith("renewals2d")):
        _table(lines, _stamp_line(key, data[key]) + "; `whiten+local+critical`, ratio to i.i.d.",
               ["target", "M", "unbounded", "bounded"], data[key]["rows"], ["target", "m"],
               lambda r: [f"{r['unbounded']:.3g}", f"{r['bounded']:.3g}"])
    for key in sorted(k for k in data if k.startswith("renewals") and "renewals" in data[k]["rows"][0]):
        _table(lines, _stamp_line(key, data[key]) + "; `knn+whiten`, 10-D Gaussian",
               ["M", "seed", "renewal", "cov in y at renewals: min eigenvalue (min over renewals 2..)",
                "max eigenvalue (max)", "map L L^T eigenvalues (min, max over renewals)", "energy distance",
                "i.i.d.", "ratio to i.i.d.", "var ratio min-max"], data[key]["rows"], ["m", "seed", "renewal"],
               lambda r: [f"{min(e[0] for e in r['renewals'][1:]):.2g}",
                          f"{max(e[1] for e in r['renewals'][1:]):.3g}",
                          f"{min(e[2] for e in r['renewals']):.2g}, {max(e[3] for e in r['renewals']):.3g}",
                          f"{r['energy']:.4g}", f"{r['iid_energy']:.4g}", f"**{r['ratio_to_iid']:.2f}**",
                          f"{r['var_ratio_min']:.2f}-{r['var_ratio_max']:.2f}"])
    if "probes" in data:
        lines += [_stamp_line("probes", data["probes"]), ""]
        lines += [f"* `{key}`: {json.dumps(value, default=float)}" for key, value in data["probes"].items()
                  if isinstance(value, dict)] + [""]
    if "timing" in data:
        lines += [f"Neighbour search, one k = 20 query of M points ({data['timing']['utc']} UTC, load "
                  f"{data['timing']['load'][0]:.1f}; median of 3 rounds):", "",
                  "| d | M | cKDTree query s | brute force (cdist + argpartition) s |", "| --- | --- | --- | --- |"]
        for key, row in data["timing"]["median"].items():
            d, m = key[1:].split("_m")
            lines.append(f"| {d} | {m} | {row['tree']:.4f} | {row['brute']:.4f} |")
    text = "\n".join(lines) + "\n"
    (args.out / "tables.md").write_text(text)
    print(text)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("part", choices=["stationary", "gaussian10d", "logistic", "timing", "probes", "renewals",
                                               "renewals2d", "ratio_weights", "tables"])
    parser.add_argument("--sizes", type=int, nargs="+", default=[100, 500])
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--first-seed", type=int, default=0, help="gaussian10d: seeds first-seed .. + repeats - 1")
    parser.add_argument("--steps", type=int, default=1000)
    parser.add_argument("--stationary-steps", type=int, nargs="+", default=[3000])
    parser.add_argument("--configs", nargs="+", default=list(CONFIGS), choices=list(CONFIGS))
    parser.add_argument("--tag", default="main", help="suffix of the results.json key")
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args(argv)
    STARTED.update(git=_git_revision(), utc=time.strftime("%Y-%m-%d %H:%M:%S", time.gmtime()))
    args.out.mkdir(parents=True, exist_ok=True)
    dict(stationary=part_stationary, gaussian10d=part_gaussian10d, logistic=part_logistic,
         timing=part_timing, probes=part_probes, renewals=part_renewals,
         renewals2d=part_renewals2d, ratio_weights=part_ratio_weights, tables=part_tables)[args.part](args)


if __name__ == "__main__":
    main()
