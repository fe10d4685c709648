"""Where a FanCalculator evaluation spends its time: rebuild and warm, 2D/3D, 1 and 2 threads.

Wraps the package's internal steps (module-level functions and methods, looked up by
name; names that do not exist in the checkout are skipped) with wall-clock timers, then
runs FanCalculator evaluations on the benchmark system of ``bench_lammps.py``
(periodic jittered lattice, h = 2.6 dx):

* ``rebuild``: every particle moved by 0.6 skin, so the Verlet list is rebuilt;
* ``warm``: moved by 1e-3 dx, list reused.

Each step's median over ``--repeats`` evaluations is printed in ms, with ``other`` the
evaluation's median time minus the timed steps (ASE, calculator Python, numpy). On one
thread the clock is the thread's CPU time (robust to the load of other processes on this
shared machine), on two threads wall time.
Steps nest (``update`` contains the bin and scan steps): nested steps are indented.

    python benchmarks/profile_fan.py [--n 1e5] [--dims 2,3] [--threads 1,2] [--repeats 7]

Writes ``benchmarks/results/profile_fan.json``.
"""
from __future__ import annotations

import argparse
import functools
import importlib
import os
import time
from collections import defaultdict
from pathlib import Path

import numba
import numpy as np
from ase.calculators.calculator import all_changes

try:
    from _provenance import write_json
except ImportError:
    from benchmarks._provenance import write_json

# (label, "module:attribute" or "module:Class.method", nesting depth)
STEPS = [
    ("prepare (checks, copy)", "ase_sphrelax.calculators.base:SPHCalculator.prepare", 0),
    ("update", "ase_sphrelax.neighbors:NeighborList.update", 1),
    ("validity check", "ase_sphrelax.neighbors:_max_displacement2", 2),
    ("extended points", "ase_sphrelax.neighbors:_extended_points", 2),
    ("bin sort", "ase_sphrelax.neighbors:_bin_sort", 2),
    ("sorted arrays", "ase_sphrelax.neighbors:_sorted_arrays", 2),
    ("list scan (one pass)", "ase_sphrelax.neighbors:NeighborList._complete_pending", 2),
    ("pair compute", "ase_sphrelax.pairs:PairInteraction.compute", 0),
    ("extend (positions)", "ase_sphrelax.neighbors:BinnedPoints.extend", 1),
    ("pair loop (list walk)", "ase_sphrelax.pairs:run_chunks", 1),
    ("bin scan + list + pairs (fused)", "ase_sphrelax.neighbors:NeighborList.fused_build", 1),
    ("fold threads", "ase_sphrelax.neighbors:fold_thread_parts", 1),
    ("fold threads (stacked buffers)", "ase_sphrelax.neighbors:fold_thread_buffers", 1),
]

TIMES: dict = defaultdict(float)
CLOCK = {"now": time.perf_counter}


def _wrap(label, fn):
    @functools.wraps(fn)
    def timed(*args, **kwargs):
        t0 = CLOCK["now"]()
        try:
            return fn(*args, **kwargs)
        finally:
            TIMES[label] += CLOCK["now"]() - t0
    return timed


def instrument():
    """Replace every step that exists by its timed wrapper; return the labels found."""
    found = []
    for label, target, depth in STEPS:
        module_name, attr = target.split(":")
        module = importlib.import_module(module_name)
        owner, name = module, attr
        if "." in attr:
            cls_name, name = attr.split(".")
            owner = getattr(module, cls_name, None)
        if owner is None or not hasattr(owner, name):
            continue
        setattr(owner, name, _wrap(label, getattr(owner, name)))
        found.append((label, depth))
    return found


def profile(n, dim, threads, repeats):
    from ase_sphrelax import FanCalculator
    from ase_sphrelax.build import periodic_box

    numba.set_num_threads(threads)
    # one thread: the CPU time of the (only) working thread, robust to other processes' load;
    # two threads: wall time
    CLOCK["now"] = time.thread_time if threads == 1 else time.perf_counter
    clock = CLOCK["now"]
    side = int(round(n ** (1.0 / dim)))
    atoms = periodic_box((side,) * dim, dx=1.0, dim=dim, lattice="square" if dim == 2 else "cubic",
                         jitter=0.25, seed=0)
    h = 2.6
    calc = FanCalculator(h=h, dx=1.0, dim=dim)
    rng = np.random.default_rng(1)
    for _ in range(3):  # compile, first (one-shot) and second (list) evaluation
        calc.calculate(atoms, ["energy", "forces"], all_changes)
    out = {}
    for case in ("rebuild", "warm"):
        per_step = defaultdict(list)
        totals = []
        builds0 = calc.nlist.builds
        for _ in range(repeats):
            if case == "rebuild":
                atoms.positions[:, 0] += 0.6 * calc.skin
            else:
                atoms.positions[:, :dim] += rng.uniform(-1e-3, 1e-3, (len(atoms), dim))
            TIMES.clear()
            t0 = clock()
            calc.calculate(atoms, ["energy", "forces"], all_changes)
            totals.append(clock() - t0)
            for label, t in TIMES.items():
                per_step[label].append(t)
        rebuilt = calc.nlist.builds - builds0
        assert rebuilt == (repeats if case == "rebuild" else 0), (case, rebuilt)
        out[case] = dict(total=float(np.median(totals)),
                         steps={label: float(np.median(v)) for label, v in per_step.items()})
    return len(atoms), out


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--n", type=float, default=1e5)
    parser.add_argument("--dims", default="2,3")
    parser.add_argument("--threads", default="1,2")
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--out", default=str(Path(__file__).parent / "results" / "profile_fan.json"))
    args = parser.parse_args(argv)
    found = instrument()
    result = dict(started=time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()), load_average_start=os.getloadavg(),
                  runs=[])
    print(f"load average {os.getloadavg()}")
    for dim in [int(d) for d in args.dims.split(",")]:
        for threads in [int(t) for t in args.threads.split(",")]:
            n, out = profile(args.n, dim, threads, args.repeats)
            result["runs"].append(dict(dim=dim, n=n, threads=threads, **out))
            clock = "CPU" if threads == 1 else "wall"
            print(f"\n{dim}D N={n} threads={threads} (median of {args.repeats}, ms, {clock} time)")
            print(f"  {'step':34s} {'rebuild':>9s} {'warm':>9s}")
            for case_total in ("total",):
                print(f"  {'evaluation (calculate)':34s} {1e3 * out['rebuild']['total']:9.2f} "
                      f"{1e3 * out['warm']['total']:9.2f}")
            timed_top = {c: 0.0 for c in out}
            for label, depth in found:
                vals = [out[c]["steps"].get(label, 0.0) for c in ("rebuild", "warm")]
                if depth == 0:
                    for c, v in zip(("rebuild", "warm"), vals):
                        timed_top[c] += v
                if max(vals) == 0.0:
                    continue
                print(f"  {'  ' * (depth + 1) + label:34s} {1e3 * vals[0]:9.2f} {1e3 * vals[1]:9.2f}")
            print(f"  {'  other (ASE, calculator, numpy)':34s} "
                  f"{1e3 * (out['rebuild']['total'] - timed_top['rebuild']):9.2f} "
                  f"{1e3 * (out['warm']['total'] - timed_top['warm']):9.2f}", flush=True)
    result["load_average_end"] = os.getloadavg()
    print(f"\nload average {os.getloadavg()}")
    write_json(args.out, result)


if __name__ == "__main__":
    main()
