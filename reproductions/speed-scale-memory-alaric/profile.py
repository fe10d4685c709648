"""Where ALARIC's peak memory goes: bench_scale.py's alaric2d/alaric3d step child, instrumented (issue 33 item 4).

The child's procedure (``benchmarks/bench_scale.py``: warm-up, the start built, the peak-RSS counter reset, then
``--steps`` ALARICDynamics steps), with the resident set (VmRSS) and its peak (VmHWM) read around the calls that
make the peak (neighbour-list update, H-solve pass and update, pressure and viscosity sums, the calculator's
evaluation, the dynamics' step), in bytes per particle above the baseline. ``--trim``: at each step's start the
resident set is read before and after glibc's ``malloc_trim(0)`` (the heap's free pages that the allocator held),
a diagnostic that changes the later figures. ``--inventory``: tracemalloc's live numpy arrays (and Python objects) at
the end of the run, by the line that allocated them (what stays between steps; numba's own allocations are not
traced).

    python reproductions/speed-scale-memory-alaric/profile.py --method alaric2d --n 1e5 --out results/profile_2d.json
"""
from __future__ import annotations

import argparse
import ctypes
import functools
import json
import sys
import tracemalloc
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))
import bench_scale as B  # noqa: E402

WRAPPED = (("neighbors", "NeighborList", "update"), ("sph", None, "_solve_pass"),
           ("sph", None, "_smoothing_length_step"), ("sph", None, "solve_smoothing_lengths"),
           ("sph", None, "pressure_forces"), ("sph", None, "viscosity_forces"),
           ("calculators.alaric", "ALARICCalculator", "evaluate"),
           ("calculators.alaric", "ALARICCalculator", "viscous_forces"),
           ("drivers.alaric_dynamics", "ALARICDynamics", "step"))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--method", default="alaric2d", choices=("alaric2d", "alaric3d"))
    parser.add_argument("--n", type=float, default=1e5)
    parser.add_argument("--steps", type=int, default=5)
    parser.add_argument("--trim", action="store_true")
    parser.add_argument("--inventory", action="store_true")
    parser.add_argument("--out", required=True)
    args = parser.parse_args()
    import importlib

    import numba

    numba.set_num_threads(1)
    _, warm = B.setup(args.method, 2000 if B.DIM[args.method] == 2 else 3000)
    warm(3)
    start, run = B.setup(args.method, args.n)
    n = len(start)
    libc = ctypes.CDLL(None)
    events, state = [], dict(depth=0, base=0)

    def per(x):
        return round((x - state["base"]) / n, 1)

    def wrap(module, owner, name):
        target = importlib.import_module(f"ase_sphrelax.{module}")
        holder = getattr(target, owner) if owner else target
        f = getattr(holder, name)
        label = f"{owner or module}.{name}"

        @functools.wraps(f)
        def g(*a, **k):
            if args.trim and name == "step":
                before = B._status("VmRSS")
                libc.malloc_trim(0)
                events.append(dict(call="malloc_trim at the step's start", rss_before=per(before),
                                   rss_after=per(B._status("VmRSS"))))
            rss, hwm = B._status("VmRSS"), B._status("VmHWM")
            state["depth"] += 1
            try:
                return f(*a, **k)
            finally:
                state["depth"] -= 1
                hwm_out = B._status("VmHWM")
                events.append(dict(call=label, depth=state["depth"], rss_in=per(rss), hwm_out=per(hwm_out),
                                   rss_out=per(B._status("VmRSS")), raised_peak=hwm_out > hwm))
        setattr(holder, name, g)

    for spec in WRAPPED:
        wrap(*spec)
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")
    state["base"] = B._status("VmRSS")
    if args.inventory:
        tracemalloc.start(8)
    run(args.steps)
    out = dict(method=args.method, n=n, steps=args.steps, trim=args.trim, version=B.git_version(),
               bytes_per_particle=per(B._status("VmHWM")), events=events)
    if args.inventory:
        snap = tracemalloc.take_snapshot()
        out["traced_live_bytes_per_particle"] = round(sum(s.size for s in snap.statistics("filename")) / n, 1)
        rows = []
        for stat in snap.statistics("traceback"):
            if stat.size / n < 4:
                break
            frames = [f"{Path(fr.filename).name}:{fr.lineno}" for fr in stat.traceback][-4:]
            rows.append(dict(bytes_per_particle=round(stat.size / n, 1), blocks=stat.count,
                             allocated_at=" < ".join(reversed(frames))))
        out["inventory"] = rows
    Path(args.out).write_text(json.dumps(out, indent=1) + "\n")
    print(f"{args.method} N={n}: peak {out['bytes_per_particle']} B per particle")


if __name__ == "__main__":
    main()
