"""Supplement to run.py, added after its run (not part of the declared protocol): Diehl's schedule for WVT with
larger initial steps mu0, on the same start and the same declared measure, and the goal ratios of run.py's ALARIC
runs against them (ALARIC's checkpoints and times from run.py's results.json).

With the default mu0 (0.002) the count of large moves only falls from this start, so Diehl's reduction never
fires; WVTICs starts with a step that moves 10-80 % of the particles by more than a spacing.

    OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 python reproductions/alaric-fig13-declared/supplement.py \
        --out reproductions/alaric-fig13-declared/results
"""
from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

from run import goal, run_wvt


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mu0", default="0.005,0.01,0.02")
    ap.add_argument("--steps", type=int, default=10000)
    ap.add_argument("--out", default="reproductions/alaric-fig13-declared/results")
    args = ap.parse_args()
    out = Path(args.out)
    main_run = json.loads((out / "results.json").read_text())
    n, seed = main_run["n"], main_run["seed"]
    run_wvt(200, 3, seed, "diehl", "mirror")  # compile
    runs = []
    for mu0 in (float(v) for v in args.mu0.split(",")):
        runs.append(run_wvt(n, args.steps, seed, "diehl", "mirror", mu0=mu0))
        print({k: v for k, v in runs[-1].items() if k != "trace"}, flush=True)
    alarics = [r for r in main_run["runs"] if r["kind"] == "alaric"]
    goals = [goal(a, w, c) for a in alarics for w in runs for c in ("wall_s", "cpu_s")]
    command = (f"python reproductions/alaric-fig13-declared/supplement.py --mu0 {args.mu0} --steps {args.steps} "
               f"--out {args.out}")
    threads = dict(OMP_NUM_THREADS=os.environ.get("OMP_NUM_THREADS"), NUMBA_NUM_THREADS=os.environ.get(
        "NUMBA_NUM_THREADS"))
    (out / "supplement.json").write_text(json.dumps(dict(command=command, threads=threads, n=n, seed=seed, runs=runs,
                                                         goals=goals), indent=1) + "\n")
    for g in goals:
        print(g, flush=True)


if __name__ == "__main__":
    main()
