"""Fan 2D's step at 1e5 on one thread with the neighbour list's two closing copies, interleaved in one process.

A: the list copied with a plain ``dst[:] = src`` (the code before the memory change), B: ``_copy_releasing`` (the
scan buffer's pages given back as they are copied). Each round builds a fresh calculator on a copy of the same
start, runs 2 steps (the first build), then times 40 steps of CPU time; rounds alternate A, B, A, B, ...

    NUMBA_NUM_THREADS=1 python reproductions/speed-scale-memory/ab_fan.py --rounds 4 \
        --out reproductions/speed-scale-memory/results/ab_fan.json
"""
import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))
sys.path.insert(0, str(ROOT))

import numba  # noqa: E402
import numpy as np  # noqa: E402

import ase_sphrelax.neighbors as nb  # noqa: E402
import bench_scale as bs  # noqa: E402
from ase_sphrelax import FanCalculator, make_optimizer  # noqa: E402


def plain(dst, src):
    dst[:] = src


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=4)
    ap.add_argument("--steps", type=int, default=40)
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    numba.set_num_threads(1)
    releasing = nb._copy_releasing
    _, warm = bs.setup("fan2d", 2000)
    warm(3)
    domain, dx, atoms = bs._fan_scene(2, 1e5)
    rows = {"A_plain": [], "B_releasing": []}
    builds = {"A_plain": 0, "B_releasing": 0}
    for _ in range(args.rounds):
        for name, fn in (("A_plain", plain), ("B_releasing", releasing)):
            nb._copy_releasing = fn
            a = atoms.copy()
            a.calc = FanCalculator(h=2.6 * dx, dx=dx, domain=domain)
            opt = make_optimizer("fan", a)
            opt.run(fmax=0.0, steps=2)
            c0 = time.process_time()
            opt.run(fmax=0.0, steps=args.steps)
            rows[name].append((time.process_time() - c0) / args.steps)
            builds[name] += a.calc.nlist.builds
    nb._copy_releasing = releasing
    out = dict(n=len(atoms), steps=args.steps, rounds=args.rounds, cpu_per_step=rows, builds=builds,
               median={k: float(np.median(v)) for k, v in rows.items()},
               ratio_B_over_A=float(np.median(rows["B_releasing"]) / np.median(rows["A_plain"])))
    text = json.dumps(out, indent=1)
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(text)
    print(text)


if __name__ == "__main__":
    main()
