"""FanCalculator of this checkout against a baseline checkout, interleaved in one run.

Measures what a change of the core must keep (issue "Core for four methods", item 2):

* one energy+forces evaluation of FanCalculator, cold (fresh calculator: one-shot bin scan)
  and warm (Verlet list reused, positions moved by 0.02 dx), at N = 1e5 in 2D (316^2) and
  3D (46^3), periodic, jitter 0.25 dx, h = 2.6 dx: single-thread CPU time, and wall time on
  2 threads;
* the compile time: import plus the first evaluation at N = 1e4 (2D) in a fresh process,
  with a cold numba cache (an empty ``NUMBA_CACHE_DIR``) and then with it warm.

Every measurement runs in a fresh subprocess with ``PYTHONPATH`` set to the checkout, the
two checkouts alternating, ``--rounds`` times; each process reports the median of
``--repeats`` calls and the table gives the median over rounds (min-max in brackets).

    git worktree add /tmp/baseline <commit>          # the baseline checkout
    python benchmarks/bench_core_vs_baseline.py --baseline /tmp/baseline

Writes ``benchmarks/results/core_vs_baseline.json``.
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
SYSTEMS = {"2D 1e5": (2, 316), "3D 1e5": (3, 46)}


# -- worker: runs inside the measured checkout -------------------------------------------------
def _worker_speed(threads, repeats):
    import numba
    import numpy as np
    from ase.calculators.calculator import all_changes

    from ase_sphrelax import FanCalculator
    from ase_sphrelax.build import periodic_box

    numba.set_num_threads(threads)
    clock = time.process_time if threads == 1 else time.perf_counter
    out = {}
    for label, (dim, side) in SYSTEMS.items():
        atoms = periodic_box(side, dx=1.0, dim=dim, lattice="square" if dim == 2 else "cubic", jitter=0.25, seed=0)
        moved = atoms.copy()
        moved.positions[:, :dim] += np.random.default_rng(1).uniform(-0.01, 0.01, (len(atoms), dim))

        def evaluate(calc, a):
            calc.calculate(a, ["energy", "forces"], all_changes)

        evaluate(FanCalculator(h=2.6, dx=1.0, dim=dim), atoms)  # compile / load outside the timings
        cold, warm = [], []
        for _ in range(repeats):
            calc = FanCalculator(h=2.6, dx=1.0, dim=dim)
            t0 = clock()
            evaluate(calc, atoms)
            cold.append(clock() - t0)
            evaluate(calc, atoms)  # builds the reusable list
            builds = calc.nlist.builds
            for a in (moved, atoms):
                t0 = clock()
                evaluate(calc, a)
                warm.append(clock() - t0)
            assert calc.nlist.builds == builds, "warm calls rebuilt the list"
        out[label] = dict(cold=float(np.median(cold)), warm=float(np.median(warm)))
    return out


def _worker_compile():
    t0 = time.perf_counter()
    from ase_sphrelax import FanCalculator
    from ase_sphrelax.build import periodic_box

    t1 = time.perf_counter()
    atoms = periodic_box(100, dx=1.0, jitter=0.25, seed=0)
    FanCalculator(h=2.6, dx=1.0).get_forces(atoms)
    t2 = time.perf_counter()
    return dict(import_s=t1 - t0, first_eval_s=t2 - t1, total_s=t2 - t0)


# -- driver ------------------------------------------------------------------------------------
def _run(checkout, mode, env_extra=None, threads=1, repeats=5):
    env = dict(os.environ, PYTHONPATH=str(checkout), OMP_NUM_THREADS="2")
    env.update(env_extra or {})
    cmd = [sys.executable, __file__, "--worker", mode, "--threads", str(threads), "--repeats", str(repeats)]
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True, check=True)
    return json.loads(proc.stdout.strip().splitlines()[-1])


def _median(values):
    values = sorted(values)
    n = len(values)
    return values[n // 2] if n % 2 else 0.5 * (values[n // 2 - 1] + values[n // 2])


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--baseline", help="path of the baseline checkout (required)")
    parser.add_argument("--current", default=str(HERE.parent), help="path of the measured checkout (this one)")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--repeats", type=int, default=5, help="calls per process (median)")
    parser.add_argument("--worker", choices=("speed", "compile"), help=argparse.SUPPRESS)
    parser.add_argument("--threads", type=int, default=1, help=argparse.SUPPRESS)
    parser.add_argument("--out", default=str(HERE / "results" / "core_vs_baseline.json"))
    args = parser.parse_args(argv)
    if args.worker == "speed":
        print(json.dumps(_worker_speed(args.threads, args.repeats)))
        return
    if args.worker == "compile":
        print(json.dumps(_worker_compile()))
        return
    if args.baseline is None:
        parser.error("--baseline is required")

    sys.path.insert(0, str(HERE))
    from _provenance import git_version

    checkouts = {"baseline": Path(args.baseline).resolve(), "current": Path(args.current).resolve()}
    load_before = os.getloadavg()
    started = datetime.datetime.now(datetime.timezone.utc)
    samples = {name: {"1 thread (CPU s)": [], "2 threads (wall s)": [], "compile cold": [], "compile warm": []}
               for name in checkouts}
    for k in range(args.rounds):
        for name, path in checkouts.items():
            samples[name]["1 thread (CPU s)"].append(_run(path, "speed", threads=1, repeats=args.repeats))
            samples[name]["2 threads (wall s)"].append(_run(path, "speed", threads=2, repeats=args.repeats))
            with tempfile.TemporaryDirectory(prefix="numba_cache_") as cache:
                env = {"NUMBA_CACHE_DIR": cache}
                samples[name]["compile cold"].append(_run(path, "compile", env))
                samples[name]["compile warm"].append(_run(path, "compile", env))
        print(f"round {k + 1}/{args.rounds} done, load {os.getloadavg()[0]:.2f}", flush=True)
    load_after = os.getloadavg()

    table = {}
    for name in checkouts:
        table[name] = {}
        for kind in ("1 thread (CPU s)", "2 threads (wall s)"):
            for label in SYSTEMS:
                for phase in ("cold", "warm"):
                    values = [s[label][phase] for s in samples[name][kind]]
                    table[name][f"{label} {phase}, {kind}"] = (_median(values), min(values), max(values))
        for kind in ("compile cold", "compile warm"):
            values = [s["total_s"] for s in samples[name][kind]]
            table[name][f"import + first eval 1e4, {kind} cache (s)"] = (_median(values), min(values), max(values))

    print(f"\nFanCalculator, current / baseline; median over {args.rounds} interleaved rounds "
          f"(each the median of {args.repeats} calls), min-max in brackets")
    print(f"{'measure':52s} {'baseline':>24s} {'current':>24s} {'ratio':>6s}")
    ratios = {}
    for key in table["baseline"]:
        b, c = table["baseline"][key], table["current"][key]
        ratios[key] = c[0] / b[0]
        print(f"{key:52s} {b[0]:9.4f} [{b[1]:.4f}-{b[2]:.4f}] {c[0]:9.4f} [{c[1]:.4f}-{c[2]:.4f}] {ratios[key]:6.3f}")
    print(f"load average before {load_before[0]:.2f}, after {load_after[0]:.2f} (1 min)")
    result = dict(date_utc=started.isoformat(timespec="seconds"), git=git_version(),
                  baseline=str(checkouts["baseline"]),
                  baseline_git=subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=checkouts["baseline"],
                                              capture_output=True, text=True).stdout.strip(),
                  load_average_before=load_before, load_average_after=load_after, rounds=args.rounds,
                  repeats=args.repeats, table=table, ratios=ratios, samples=samples)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(result, indent=1))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
