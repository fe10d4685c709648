"""Time per step of SPH-ParVI (cell lists, O(M)) against SVGD (all pairs, O(M^2)) in 2D (issue 8, item 6).

    .venv/bin/python benchmarks/bench_sampling_speed.py [--sizes 1e2 3e2 1e3 3e3 1e4 3e4 1e5] [--svgd-max 3e4]

One step of each on M points of the 2D standard normal: SPH-ParVI's default (adaptive-h density solve,
pressure and viscosity passes, score; the Verlet list reused as in a run) and SVGD's Stein direction
(median heuristic, RBF kernel in row blocks, Adam). Each is the median of ``--repeats`` timed steps after a
warm-up step, both timed in the same run. SVGD above ``--svgd-max`` is extrapolated from the fit (marked).
Writes ``benchmarks/results/bench_sampling_speed.json`` with the times, the fitted exponents (log-log
least squares) and the crossover M where SVGD's fit exceeds SPH-ParVI's; prints the load average.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _provenance import git_version  # noqa: E402

from ase_sphrelax.models.parvi import CountingTarget, ParVIModel  # noqa: E402
from ase_sphrelax.sampling import baselines, get_target  # noqa: E402

OUT = Path(__file__).resolve().parent / "results" / "bench_sampling_speed.json"


def time_sph(m, repeats):
    target = get_target("gaussian")
    model = ParVIModel(CountingTarget(target.log_density, target.score, 2), 2)
    x = target.sample(m, np.random.default_rng(0))
    v = np.zeros_like(x)
    model.evaluate(x, v)  # warm-up: compiles, builds the list
    times = []
    rng = np.random.default_rng(1)
    for _ in range(repeats):
        x = x + 1e-4 * rng.standard_normal(x.shape)  # a step's worth of motion: the list is reused
        t0 = time.perf_counter()
        model.evaluate(x, v)
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def time_svgd(m, repeats):
    target = get_target("gaussian")
    x = target.sample(m, np.random.default_rng(0))
    opt = baselines.Adam(0.05)
    times = []
    for _ in range(repeats + 1):
        t0 = time.perf_counter()
        ell = baselines.median_length_scale(x)
        phi = baselines.svgd_direction(x, target.score(x), ell)
        x = x + opt.update(-phi)
        times.append(time.perf_counter() - t0)
    return float(np.median(times[1:]))


def fit(ms, ts):
    slope, intercept = np.polyfit(np.log(ms), np.log(ts), 1)
    return float(slope), float(intercept)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", nargs="+", type=float, default=[1e2, 3e2, 1e3, 3e3, 1e4, 3e4, 1e5])
    parser.add_argument("--svgd-max", type=float, default=3e4)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args(argv)
    load = os.getloadavg()
    print(f"load average {load}")
    rows = []
    for m in (int(s) for s in args.sizes):
        sph_t = time_sph(m, args.repeats)
        svgd_t = time_svgd(m, args.repeats) if m <= args.svgd_max else None
        rows.append(dict(m=m, sph=sph_t, svgd=svgd_t))
        print(f"M = {m:7d}: SPH-ParVI {sph_t * 1e3:9.2f} ms/step, SVGD "
              + (f"{svgd_t * 1e3:9.2f} ms/step, ratio SVGD/SPH {svgd_t / sph_t:7.2f}" if svgd_t else "(not run)"),
              flush=True)
    ms = np.array([r["m"] for r in rows], dtype=float)
    sph_exp, sph_c = fit(ms, [r["sph"] for r in rows])
    measured = [r for r in rows if r["svgd"] is not None]
    svgd_exp, svgd_c = fit([r["m"] for r in measured], [r["svgd"] for r in measured])
    for r in rows:
        if r["svgd"] is None:
            r["svgd_extrapolated"] = float(np.exp(svgd_c) * r["m"] ** svgd_exp)
        else:
            r["svgd_over_sph"] = r["svgd"] / r["sph"]  # how many times faster SPH-ParVI's step is
    # crossover: exp(svgd_c) M^a = exp(sph_c) M^b
    crossover = float(np.exp((sph_c - svgd_c) / (svgd_exp - sph_exp))) if svgd_exp != sph_exp else None
    measured_crossover = None
    for a, b in zip(measured, measured[1:]):
        ra, rb = np.log(a["svgd"] / a["sph"]), np.log(b["svgd"] / b["sph"])
        if ra <= 0 < rb:  # SVGD cheaper at a, dearer at b: interpolate log(ratio) linearly in log M
            measured_crossover = float(np.exp(np.log(a["m"]) + (0 - ra) / (rb - ra) * np.log(b["m"] / a["m"])))
    big = [r for r in rows if r["m"] >= 1000]
    sph_exp_large = fit([r["m"] for r in big], [r["sph"] for r in big])[0] if len(big) > 1 else None
    big_svgd = [r for r in measured if r["m"] >= 1000]
    svgd_exp_large = fit([r["m"] for r in big_svgd], [r["svgd"] for r in big_svgd])[0] if len(big_svgd) > 1 else None
    result = dict(git=git_version(), load_average=load, rows=rows, sph_exponent=sph_exp, svgd_exponent=svgd_exp,
                  sph_exponent_m_ge_1000=sph_exp_large, svgd_exponent_m_ge_1000=svgd_exp_large,
                  crossover_m_fit=crossover, crossover_m_measured=measured_crossover)
    print(f"exponents (all M): SPH-ParVI {sph_exp:.2f}, SVGD {svgd_exp:.2f}; (M >= 1000): {sph_exp_large}, "
          f"{svgd_exp_large}; crossover M from the fits {crossover:.3g}, from the measured ratios {measured_crossover}")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=1))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
