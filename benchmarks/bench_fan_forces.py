"""FanCalculator (numba cell list) vs a plain numpy + scipy cKDTree version: one energy+forces evaluation.

Systems (periodic, jittered square/cubic lattice, jitter 0.25 dx, h = 2.6 dx):

* 2D, N = 1e4, 1e5, 1e6 (100^2, 316^2, 1000^2), about 21 neighbours;
* 3D, N = 1e5 (46^3) at the same h = 2.6 dx: the same kernel resolution as in
  2D (Fan's default ratio), about 74 neighbours, i.e. 3.5x the pairs per
  particle, the case where the pair loop rather than the bookkeeping dominates.

Timings (best of ``--repeats``), each pair of codes in the same run:

* ``cold``: a fresh calculator: neighbour search (cell list / cKDTree) + kernel sums.
  FanCalculator does what its first call does (currently a bin scan fused with
  the pair sums, no list stored); the reference builds a cKDTree and calls
  ``query_pairs(h)`` (skin 0, its fastest one-shot choice).
* ``warm``: the neighbour list is reused: positions moved by at most 0.02 dx
  (< skin / 2 = 0.13 dx) since the build (FanCalculator builds its Verlet list,
  skin 0.1 h, on its second call, which is not timed). The reference keeps its
  ``query_pairs(h + skin)`` array (skin 0.1 h) the same way.

FanCalculator is timed with 1 and 2 numba threads (``numba.set_num_threads``);
the reference is single threaded (numpy + cKDTree.query_pairs). Both are
called without ASE's property cache (``calc.calculate`` with all changes). The
two results are compared (max force difference relative to max |F|, and energy).

    python benchmarks/bench_fan_forces.py               # full: 2D 1e4, 1e5, 1e6 and 3D 1e5
    python benchmarks/bench_fan_forces.py --quick       # 2D 1e4, 1e5 only, 2 repeats

Writes benchmarks/results/bench_fan_forces.json. Goals (issue item 12):
reference/ours >= 10 at N = 1e5 in 2D; time(1e6)/time(1e5) <= 11.
"""
from __future__ import annotations

import argparse
import datetime
import gc
import json
import math
import os
import platform
import sys
import time
from pathlib import Path

import numba
import numpy as np
from ase.calculators.calculator import all_changes

from ase_sphrelax import FanCalculator
from ase_sphrelax.build import periodic_box

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _provenance import git_version  # noqa: E402
from _reference import ReferenceFan  # noqa: E402

RATIO = 2.6
JITTER = 0.25
WARM_MOVE = 0.02  # dx; below skin/2 = 0.05 h = 0.13 dx
RESULTS = Path(__file__).resolve().parent / "results"

SYSTEMS = {  # label: (dim, particles per axis)
    "2D 1e4": (2, 100),
    "2D 1e5": (2, 316),
    "2D 1e6": (2, 1000),
    "3D 1e5": (3, 46),
}


def make_system(dim, side, seed=0):
    lattice = "square" if dim == 2 else "cubic"
    return periodic_box(side, dx=1.0, dim=dim, lattice=lattice, jitter=JITTER, seed=seed)


def best_of(fn, repeats):
    """Best wall and best CPU (process) time of ``repeats`` calls.

    ``fn()`` does its untimed set-up and returns the callable to time. On a shared
    machine the CPU time of a single-threaded run is the robust number (wall time
    includes waiting for a core); with 2 threads CPU time adds both threads.
    """
    best, best_cpu = math.inf, math.inf
    for _ in range(repeats):
        run = fn()
        gc.collect()
        c0 = time.process_time()
        t0 = time.perf_counter()
        run()
        best = min(best, time.perf_counter() - t0)
        best_cpu = min(best_cpu, time.process_time() - c0)
    return best, best_cpu


def ours_eval(calc, atoms):
    calc.calculate(atoms, ["energy", "forces"], all_changes)
    return calc.results["energy"], calc.results["forces"]


def bench_system(label, dim, side, repeats, threads_list):
    atoms = make_system(dim, side)
    n = len(atoms)
    h = RATIO
    rng = np.random.default_rng(1)
    r0 = atoms.positions.copy()
    moved = []  # small displacement sets for warm calls
    for _ in range(2):
        d = np.zeros_like(r0)
        d[:, :dim] = rng.uniform(-1, 1, (n, dim)) * WARM_MOVE / math.sqrt(dim)
        moved.append(r0 + d)

    row = dict(label=label, dim=dim, n=n, h_over_dx=RATIO)

    # -- reference ----------------------------------------------------------------
    def ref_cold():
        return lambda: ReferenceFan(h, dim=dim, skin=0.0).compute(atoms)

    atoms.positions[:] = r0
    e_ref, _, f_ref = ReferenceFan(h, dim=dim).compute(atoms)
    row["ref_cold_s"], row["ref_cold_cpu_s"] = best_of(ref_cold, repeats)
    ref = ReferenceFan(h, dim=dim, skin=0.1 * h)
    ref.compute(atoms)
    assert ref.builds == 1
    state = {"k": 0}

    def ref_warm():
        atoms.positions[:] = moved[state["k"] % 2]
        state["k"] += 1
        return lambda: ref.compute(atoms)

    row["ref_warm_s"], row["ref_warm_cpu_s"] = best_of(ref_warm, repeats)
    assert ref.builds == 1, "reference warm calls rebuilt the list"
    atoms.positions[:] = r0

    # -- ours ------------------------------------------------------------------------
    row["ours"] = {}
    for threads in threads_list:
        numba.set_num_threads(threads)
        atoms.positions[:] = r0

        def ours_cold():
            calc = FanCalculator(h, dim=dim)
            return lambda: ours_eval(calc, atoms)

        cold, cold_cpu = best_of(ours_cold, repeats)
        calc = FanCalculator(h, dim=dim)
        e_ours, f_ours = ours_eval(calc, atoms)
        e_ours, f_ours = e_ours, f_ours.copy()
        ours_eval(calc, atoms)  # a calculator may build its reusable list only on the second call
        builds = calc.nlist.builds

        def ours_warm():
            atoms.positions[:] = moved[state["k"] % 2]
            state["k"] += 1
            return lambda: ours_eval(calc, atoms)

        warm, warm_cpu = best_of(ours_warm, repeats)
        assert calc.nlist.builds == builds, "warm calls rebuilt the neighbour list"
        atoms.positions[:] = r0
        row["ours"][str(threads)] = dict(cold_s=cold, warm_s=warm, cold_cpu_s=cold_cpu, warm_cpu_s=warm_cpu,
                                         speedup_cold=row["ref_cold_s"] / cold,
                                         speedup_warm=row["ref_warm_s"] / warm,
                                         speedup_cold_cpu=row["ref_cold_cpu_s"] / cold_cpu,
                                         speedup_warm_cpu=row["ref_warm_cpu_s"] / warm_cpu)
    f_scale = float(np.abs(f_ref).max())
    row["max_force_diff_rel"] = float(np.abs(f_ours - f_ref).max() / f_scale)
    row["energy_diff_rel"] = float(abs(e_ours - e_ref) / abs(e_ref))
    row["pairs_per_particle"] = float(_pairs_per_particle(atoms, h, dim))
    return row


def _pairs_per_particle(atoms, h, dim):
    ref = ReferenceFan(h, dim=dim)
    r = atoms.positions[:, :dim]
    return 2.0 * len(ref.pairs(r, np.diag(atoms.cell.array)[:dim])) / len(atoms)


def print_table(rows, threads_list, cpu=False):
    """Wall-time table (all thread counts) or CPU-time table (cpu=True)."""
    suf = "_cpu_s" if cpu else "_s"
    sp = "_cpu" if cpu else ""
    head = f"{'system':8s} {'N':>8s} {'nb':>5s} | {'ref cold':>9s} {'ref warm':>9s}"
    for t in threads_list:
        head += f" | {t}thr cold {'x':>5s} {t}thr warm {'x':>5s}"
    head += " | max dF/F"
    print(head)
    print("-" * len(head))
    for row in rows:
        line = (f"{row['label']:8s} {row['n']:8d} {row['pairs_per_particle']:5.1f} | "
                f"{row['ref_cold' + suf] * 1e3:7.1f}ms {row['ref_warm' + suf] * 1e3:7.1f}ms")
        for t in threads_list:
            o = row["ours"][str(t)]
            line += (f" | {o['cold' + suf] * 1e3:7.2f}ms {o['speedup_cold' + sp]:5.1f} "
                     f"{o['warm' + suf] * 1e3:7.2f}ms {o['speedup_warm' + sp]:5.1f}")
        line += f" | {row['max_force_diff_rel']:.1e}"
        print(line)


def scaling(rows, threads_list):
    by = {r["label"]: r for r in rows}
    out = {}
    if "2D 1e5" in by and "2D 1e6" in by:
        a, b = by["2D 1e5"], by["2D 1e6"]
        for t in threads_list:
            for kind in ("cold_s", "warm_s", "cold_cpu_s", "warm_cpu_s"):
                out[f"ours_{t}thr_{kind[:-2]}_1e6_over_1e5"] = b["ours"][str(t)][kind] / a["ours"][str(t)][kind]
        for kind in ("cold_s", "warm_s", "cold_cpu_s", "warm_cpu_s"):
            out[f"ref_{kind[:-2]}_1e6_over_1e5"] = b["ref_" + kind] / a["ref_" + kind]
        out["n_ratio"] = b["n"] / a["n"]
    return out


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="2D 1e4 and 1e5 only, 2 repeats")
    parser.add_argument("--repeats", type=int, default=None, help="best of this many (default 7, 3 for 1e6)")
    parser.add_argument("--systems", nargs="*", default=None, choices=list(SYSTEMS))
    parser.add_argument("--out", default=str(RESULTS / "bench_fan_forces.json"))
    args = parser.parse_args(argv)
    labels = args.systems or (["2D 1e4", "2D 1e5"] if args.quick else list(SYSTEMS))
    threads_list = [1, 2] if numba.config.NUMBA_NUM_THREADS >= 2 else [1]

    # compile / load the numba caches outside the timings
    warm_atoms = make_system(2, 20)
    ours_eval(FanCalculator(RATIO, dim=2), warm_atoms)
    ours_eval(FanCalculator(RATIO, dim=3), make_system(3, 8))

    load_before = os.getloadavg()
    started = datetime.datetime.now(datetime.timezone.utc)
    rows = []
    t_start = time.perf_counter()
    for label in labels:
        dim, side = SYSTEMS[label]
        repeats = args.repeats or (2 if args.quick else (3 if side ** dim >= 10**6 else 7))
        rows.append(bench_system(label, dim, side, repeats, threads_list))
        print(f"  done {label} ({time.perf_counter() - t_start:.0f} s)", flush=True)
    load_after = os.getloadavg()
    print()
    print(f"FanCalculator vs numpy+cKDTree, h = {RATIO} dx, periodic, jitter {JITTER} dx; "
          "one energy+forces evaluation, best of repeats; x = reference time / ours")
    print("WALL time:")
    print_table(rows, threads_list)
    print("CPU (process) time; for 2 threads the sum over both threads:")
    print_table(rows, threads_list, cpu=True)
    sc = scaling(rows, threads_list)
    for k, v in sc.items():
        print(f"  {k}: {v:.2f}")
    print(f"load average before {load_before[0]:.2f}, after {load_after[0]:.2f} (1 min); "
          f"numba threading layer {numba.threading_layer()}")

    goals = {}
    by = {r["label"]: r for r in rows}
    if "2D 1e5" in by:
        o = by["2D 1e5"]["ours"]["1"]
        for kind in ("cold", "warm", "cold_cpu", "warm_cpu"):
            goals[f"speedup_1e5_2d_1thread_{kind} >= 10"] = bool(o[f"speedup_{kind}"] >= 10)
    for kind in ("cold", "warm", "cold_cpu", "warm_cpu"):
        key = f"ours_1thr_{kind}_1e6_over_1e5"
        if key in sc:
            goals[f"time_1e6/time_1e5 <= 11 (1 thread, {kind})"] = bool(sc[key] <= 11)
    for k, v in goals.items():
        print(f"  goal {k}: {'met' if v else 'MISSED'}")

    out = dict(
        date_utc=started.isoformat(timespec="seconds"),
        git=git_version(),
        machine=dict(platform=platform.platform(), cpus=os.cpu_count(), python=platform.python_version(),
                     numpy=np.__version__, numba=numba.__version__,
                     threading_layer=numba.threading_layer()),
        load_average_before=load_before, load_average_after=load_after,
        h_over_dx=RATIO, jitter=JITTER, warm_move_dx=WARM_MOVE, rows=rows, scaling=sc, goals=goals,
    )
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(out, indent=1))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
