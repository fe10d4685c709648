"""ALARIC's peak memory per particle, row by row: ``benchmarks/bench_scale.py``'s step child (issue 33 item 4).

Each row (``METHOD:N:LIST``, LIST ``list`` or ``scan``) runs in a fresh process with one numba thread, by the
bench's own child procedure (``bench_scale.child_step``: warm-up, the start built, the peak-RSS counter reset,
``--steps`` ALARICDynamics steps, peak RSS minus the baseline per particle). ``list``: the bench as it is (the
calculator's default ``store_list=True``); ``scan``: the same with ``ALARICCalculator(store_list=False)`` (every
sum scans one-shot bins, no Verlet list).

    python reproductions/speed-scale-memory-alaric/run.py --rows alaric2d:1e6:list,alaric3d:1e5:list \
        --out reproductions/speed-scale-memory-alaric/results/rows.json
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))


def child(method, n, kind, steps):
    import ase_sphrelax
    import bench_scale

    if kind == "scan":  # the bench's setup imports ALARICCalculator from the package when it runs
        base = ase_sphrelax.ALARICCalculator

        class ScanALARIC(base):
            default_parameters = dict(base.default_parameters, store_list=False)

        ase_sphrelax.ALARICCalculator = ScanALARIC
    row = bench_scale.child_step(method, float(n), steps)
    return dict(row, store_list=kind == "list")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", default="alaric2d:1e6:list,alaric3d:1e5:list,alaric3d:1e5:scan")
    parser.add_argument("--steps", type=int, default=5)
    parser.add_argument("--out", default=None)
    parser.add_argument("--child", nargs=3, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(child(*args.child, args.steps)))
        return
    from _provenance import git_version

    env = dict(os.environ, NUMBA_NUM_THREADS="1", OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    rows = []
    for spec in args.rows.split(","):
        method, n, kind = spec.split(":")
        if kind not in ("list", "scan"):
            raise SystemExit(f"--rows: the third field must be list or scan, got {kind!r}")
        out = subprocess.run([sys.executable, __file__, "--steps", str(args.steps), "--child", method, n, kind],
                             env=env, capture_output=True, text=True)
        if out.returncode:
            raise SystemExit(f"{spec}: {out.stderr.strip().splitlines()[-1]}")
        rows.append(json.loads(out.stdout.strip().splitlines()[-1]))
        print(f"{spec}: {rows[-1]['bytes_per_particle']:.0f} B per particle", flush=True)
    result = dict(version=git_version(), load=os.getloadavg(), steps=args.steps, rows=rows)
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(json.dumps(result, indent=1) + "\n")


if __name__ == "__main__":
    main()
