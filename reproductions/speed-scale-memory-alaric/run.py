"""ALARIC's peak memory per particle, row by row: ``benchmarks/bench_scale.py``'s step child (issue 33 item 4).

Each row (``METHOD:N:KIND``, KIND ``list``, ``scan``, ``release`` or ``mmap``; METHOD any of the bench's) runs in a
fresh process with one numba thread, by the bench's own child procedure (``bench_scale.child_step``: warm-up, the
start built, the peak-RSS counter reset, ``--steps`` steps, peak RSS minus the baseline per particle). ``list``: the
bench with ``ALARICCalculator(store_list=True)`` (the default until ``store_list=None``, a list in 2D and none in
3D); ``scan``: the same with
``ALARICCalculator(store_list=False)`` (every sum scans one-shot bins, no Verlet list). Two diagnostics of the list
rows: ``release``, every pair sum gives its scratch pages, gathered inputs and the heap's free pages back as it does
from ``pairs.RELEASE_MIN_POINTS`` points (the constant set to 1 in the child); ``mmap``, glibc's mmap threshold
fixed at 64 KiB once the start is built (``mallopt``: every array above it is its own mapping, unmapped when freed,
so the peak is the live data without the heap's kept pages; since commit a9d76d0 the H solve fixes it so, and
``mmap`` rows are ``list`` rows; set after the start is built, the start's freed temporaries stay in the heap, inside
the baseline, for the steps to reuse: lower rows than a threshold fixed from the warm-up on). ALARIC's rows add the
stored list's size at the end (its int32 buffer, and the points, particles and mirror ghosts, per particle).

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

    if kind == "release":  # every sum releases (pairs.py reads the constant at each call)
        import ase_sphrelax.calculators.alaric as calc_alaric
        import ase_sphrelax.pairs as pairs

        pairs.RELEASE_MIN_POINTS = calc_alaric.RELEASE_MIN_POINTS = 1
    if kind == "mmap":  # after the warm-up (whose setup is at another size): the measured run only
        import ctypes

        plain_setup = bench_scale.setup  # its own name: ``setup`` is bound again below (a closure would recurse)

        def fixed_threshold_setup(method_, n_):
            out = plain_setup(method_, n_)
            if n_ == float(n):
                libc = ctypes.CDLL(None)
                libc.mallopt(-3, 65536)  # M_MMAP_THRESHOLD (also ends glibc's dynamic threshold)
            return out

        bench_scale.setup = fixed_threshold_setup
    # the bench's setup imports ALARICCalculator from the package when it runs: scan rows without a Verlet list,
    # the others with one (True, the default until store_list=None made 3D list-free)
    base = ase_sphrelax.ALARICCalculator

    class RowALARIC(base):
        default_parameters = dict(base.default_parameters, store_list=kind != "scan")

    ase_sphrelax.ALARICCalculator = RowALARIC
    setup, held = bench_scale.setup, {}

    def holding_setup(method_, n_):  # the measured run's Atoms: the list's size after the steps
        start, run = setup(method_, n_)
        held["atoms"] = start
        return start, run

    bench_scale.setup = holding_setup
    row = bench_scale.child_step(method, float(n), steps)
    row = dict(row, store_list=kind != "scan", kind=kind)
    nlist = getattr(getattr(held.get("atoms"), "calc", None), "nlist", None)
    if nlist is not None and nlist.stored:  # ALARIC: its Verlet list (particles and mirror ghosts) at the end
        row.update(points_per_particle=nlist.n_extended / row["n"],
                   list_bytes_per_particle=nlist._pair_buffer.nbytes / row["n"],
                   pairs_per_particle=nlist._pair_count / row["n"])
    return row


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
        if kind not in ("list", "scan", "release", "mmap"):
            raise SystemExit(f"--rows: the third field must be list, scan, release or mmap, got {kind!r}")
        out = subprocess.run([sys.executable, __file__, "--steps", str(args.steps), "--child", method, n, kind],
                             env=env, capture_output=True, text=True)
        if out.returncode:
            raise SystemExit(f"{spec}: {out.stderr.strip().splitlines()[-1]}")
        rows.append(json.loads(out.stdout.strip().splitlines()[-1]))
        print(f"{spec}: {rows[-1]['bytes_per_particle']:.0f} B per particle", flush=True)
    result = dict(version=git_version(), command=" ".join(["python", *sys.argv]), load=os.getloadavg(),
                  steps=args.steps, rows=rows)
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(json.dumps(result, indent=1) + "\n")


if __name__ == "__main__":
    main()
