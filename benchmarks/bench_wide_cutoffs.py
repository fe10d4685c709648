"""Neighbour rebuild with cut-offs spanning two orders of magnitude, against a uniform cut-off.

The case of reproductions/speed-wide-cutoffs/README.md, "Known limit" (issue 16, item 6): M = 2e4 points of a 2D
standard normal, bounded, with SPH-ParVI's adaptive smoothing lengths H (the model's own
solve: H from about 0.03 to 3, 100x). Timed: a list rebuild (``NeighborList.update`` with
skin 0.2 median H) plus one density pass (``sph.density_sums``, which runs the fused rebuild
scan), the list and its buffers reused (the points alternate between two translates, so every
call rebuilds); and the same with a uniform cut-off at the median H. Single thread CPU time
and 2-thread wall time, median of ``--repeats`` per process.

The inputs (points and H) are made once, here, and every measurement runs in a fresh
subprocess with ``PYTHONPATH`` set to a checkout: this one, and with ``--baseline DIR`` that
one too, alternating, ``--rounds`` times. The ratio wide/uniform is taken within each
process; the table gives the median over rounds (min-max in brackets).

    python benchmarks/bench_wide_cutoffs.py --baseline /work/main

Writes ``benchmarks/results/bench_wide_cutoffs.json``.
"""
from __future__ import annotations

import argparse
import datetime
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def make_inputs(m, seed, path):
    """Points of N(0, I_2) and SPH-ParVI's adaptive H for them, saved to ``path`` (.npz)."""
    import numpy as np

    from ase_sphrelax.models.parvi import CountingTarget, ParVIModel

    x_p2 = np.random.default_rng(seed).standard_normal((m, 2))
    model = ParVIModel(CountingTarget(score=lambda x: -x), dim=2)
    _, h_p, _ = model.densities(x_p2)
    np.savez(path, x_p2=x_p2, h_p=h_p)
    return h_p


def _worker(inputs, threads, repeats):
    import numba
    import numpy as np

    from ase_sphrelax import sph
    from ase_sphrelax.kernels import get_kernel
    from ase_sphrelax.neighbors import NeighborList

    numba.set_num_threads(threads)
    clock = time.process_time if threads == 1 else time.perf_counter
    data = np.load(inputs)
    h_p = data["h_p"]
    m = h_p.shape[0]
    r_pc = np.zeros((m, 3))
    r_pc[:, :2] = data["x_p2"]
    h_med = float(np.median(h_p))
    skin = 0.2 * h_med
    moved = r_pc + [10.0 * skin, 0.0, 0.0]  # a translate: every update rebuilds, the sums are the same
    kernel = get_kernel("wendland_c2", 2)
    cell, pbc = np.zeros((3, 3)), [False] * 3
    out = {}
    for label, h in (("wide", h_p), ("uniform", h_med)):
        nlist = NeighborList(h, skin=skin)
        times = []
        for k in range(repeats + 2):  # two warm-up calls (compilation, buffers)
            x = moved if k % 2 else r_pc
            t0 = clock()
            nlist.update(x, cell, pbc, cutoff=h)
            sums = sph.density_sums(nlist, x, 1.0 / m, h, kernel)
            t1 = clock()
            if k >= 2:
                times.append(t1 - t0)
        out[label] = float(np.median(times))
        out[label + " pairs per point"] = float(len(nlist.pair_j) / m)
        out[label + " rho sum"] = float(sums.rho_p.sum())
    out["ratio"] = out["wide"] / out["uniform"]
    return out


def _alaric_worker(n, threads, repeats, warp=0.6):
    """ALARIC forces on a periodic 2D lattice warped along x (density contrast (1 + warp) / (1 - warp),
    H varying by about 2x): the first evaluation (one-shot bins), a step with the list kept, and a
    step that rebuilds it (every particle moved by 0.3 median H)."""
    import numba
    import numpy as np

    from ase_sphrelax import ALARICCalculator
    from ase_sphrelax.build import periodic_box

    numba.set_num_threads(threads)
    clock = time.process_time if threads == 1 else time.perf_counter
    side = int(round(n ** 0.5))
    atoms = periodic_box((side, side), dx=1.0, dim=2, lattice="square", jitter=0.25, seed=0)
    x = atoms.positions[:, 0]
    atoms.positions[:, 0] = x + warp * side / (2 * np.pi) * np.sin(2 * np.pi * x / side)
    rng = np.random.default_rng(1)
    times = {"cold": [], "warm": [], "rebuild": []}
    for _ in range(repeats):
        a = atoms.copy()
        a.calc = ALARICCalculator(target_density=lambda p: np.ones(len(p)),
                                  target_gradient=lambda p: np.zeros_like(p), dim=2, mass=1.0, form="log")
        t0 = clock()
        a.get_forces()
        times["cold"].append(clock() - t0)
        h_med = float(np.median(a.calc.h_p))
        for kind, size in (("warm", 1e-3), ("rebuild", 0.3 * h_med), ("warm", 1e-3)):
            a.positions[:, :2] += rng.uniform(-size, size, (len(a), 2))
            t0 = clock()
            a.get_forces()
            times[kind].append(clock() - t0)
    out = {k: float(np.median(v)) for k, v in times.items()}
    out["h max / min"] = float(a.calc.h_p.max() / a.calc.h_p.min())
    return out


def _run(checkout, inputs, threads, repeats, worker="_worker"):
    env = dict(os.environ, PYTHONPATH=str(checkout), OPENBLAS_NUM_THREADS="1")
    first = repr(str(inputs)) if worker == "_worker" else str(inputs)
    code = (f"import sys, json; sys.path.insert(0, {str(HERE)!r}); import bench_wide_cutoffs as b; "
            f"print(json.dumps(b.{worker}({first}, {threads}, {repeats})))")
    # run in the checkout: python -c puts the working directory first on sys.path
    result = subprocess.run([sys.executable, "-c", code], env=env, cwd=str(checkout), capture_output=True, text=True,
                            check=True)
    return json.loads(result.stdout.strip().splitlines()[-1])


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--baseline", type=Path, help="a checkout to compare with (e.g. /work/main)")
    parser.add_argument("--m", type=int, default=20000)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--alaric", type=int, metavar="N", help="instead: ALARIC forces on N particles (2D, H "
                        "varying about 2x) in both checkouts, cold / warm / rebuild, 1 thread")
    parser.add_argument("--out", type=Path, default=HERE / "results" / "bench_wide_cutoffs.json")
    args = parser.parse_args(argv)
    if args.alaric:
        return alaric_main(args)
    import numpy as np

    sys.path.insert(0, str(HERE))
    from _provenance import git_version, write_json

    checkouts = {"this": HERE.parent}
    if args.baseline is not None:
        checkouts["baseline"] = args.baseline.resolve()
    load_before = os.getloadavg()
    print(f"load average {load_before[0]:.2f} {load_before[1]:.2f} {load_before[2]:.2f}", flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        inputs = Path(tmp) / "inputs.npz"
        h_p = make_inputs(args.m, 0, inputs)
        print(f"M = {args.m}: H from {h_p.min():.4f} to {h_p.max():.3f} (median {np.median(h_p):.4f}, "
              f"max/min {h_p.max() / h_p.min():.0f})", flush=True)
        runs = {(name, t): [] for name in checkouts for t in args.threads}
        for k in range(args.rounds):
            for t in args.threads:
                for name, checkout in checkouts.items():
                    runs[name, t].append(_run(checkout, inputs, t, args.repeats))
            print(f"round {k + 1}/{args.rounds} done, load {os.getloadavg()[0]:.2f}", flush=True)
    load_after = os.getloadavg()

    def stat(values):
        return float(np.median(values)), float(min(values)), float(max(values))

    table = {}
    print("\n| checkout | threads | wide ms | uniform ms | wide / uniform | pairs per point wide, uniform |")
    print("| --- | --- | --- | --- | --- | --- |")
    for (name, t), results in runs.items():
        row = {key: stat([r[key] for r in results]) for key in ("wide", "uniform", "ratio")}
        row["pairs"] = (results[0]["wide pairs per point"], results[0]["uniform pairs per point"])
        row["rho sum"] = (results[0]["wide rho sum"], results[0]["uniform rho sum"])
        table[f"{name} {t} thread(s)"] = row
        w, u, r = row["wide"], row["uniform"], row["ratio"]
        print(f"| {name} | {t} | {1e3 * w[0]:.1f} ({1e3 * w[1]:.1f}-{1e3 * w[2]:.1f}) | {1e3 * u[0]:.2f} "
              f"({1e3 * u[1]:.2f}-{1e3 * u[2]:.2f}) | **{r[0]:.2f}** ({r[1]:.2f}-{r[2]:.2f}) | "
              f"{row['pairs'][0]:.1f}, {row['pairs'][1]:.1f} |")
    if "baseline" in checkouts:
        for t in args.threads:
            this, base = table[f"this {t} thread(s)"], table[f"baseline {t} thread(s)"]
            print(f"{t} thread(s): wide build this/baseline {this['wide'][0] / base['wide'][0]:.3f}, "
                  f"uniform build this/baseline {this['uniform'][0] / base['uniform'][0]:.3f}")
    print(f"load average before {load_before[0]:.2f}, after {load_after[0]:.2f}")
    write_json(args.out, {
        "benchmark": "bench_wide_cutoffs", "version": git_version(),
        "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "m": args.m, "rounds": args.rounds, "repeats": args.repeats, "load_before": load_before,
        "load_after": load_after, "h_min": float(h_p.min()), "h_median": float(np.median(h_p)),
        "h_max": float(h_p.max()), "checkouts": {k: str(v) for k, v in checkouts.items()},
        "times_s_median_min_max": table,
    })


def alaric_main(args):
    """ALARIC timings of this checkout and the baseline, alternating (the speed that must not move)."""
    import numpy as np

    sys.path.insert(0, str(HERE))
    from _provenance import git_version, write_json

    checkouts = {"this": HERE.parent, "baseline": args.baseline.resolve()}
    load_before = os.getloadavg()
    print(f"load average {load_before[0]:.2f} {load_before[1]:.2f} {load_before[2]:.2f}", flush=True)
    runs = {name: [] for name in checkouts}
    for k in range(args.rounds):
        for name, checkout in checkouts.items():
            runs[name].append(_run(checkout, args.alaric, 1, args.repeats, worker="_alaric_worker"))
        print(f"round {k + 1}/{args.rounds} done, load {os.getloadavg()[0]:.2f}", flush=True)
    table = {name: {key: float(np.median([r[key] for r in results])) for key in results[0]}
             for name, results in runs.items()}
    print(f"\nALARIC N = {args.alaric}, 1 thread CPU ms (median of {args.rounds} rounds), H max/min "
          f"{table['this']['h max / min']:.2f}")
    for key in ("cold", "warm", "rebuild"):
        print(f"{key}: this {1e3 * table['this'][key]:.1f}, baseline {1e3 * table['baseline'][key]:.1f}, "
              f"ratio {table['this'][key] / table['baseline'][key]:.3f}")
    load_after = os.getloadavg()
    print(f"load average before {load_before[0]:.2f}, after {load_after[0]:.2f}")
    write_json(args.out.with_name("bench_wide_cutoffs_alaric.json"), {
        "benchmark": "bench_wide_cutoffs --alaric", "version": git_version(), "n": args.alaric,
        "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "rounds": args.rounds, "repeats": args.repeats, "load_before": load_before, "load_after": load_after,
        "runs": runs, "median_s": table})


if __name__ == "__main__":
    main()
