"""How far list tuning can take Fan's sphere at 1e6 toward 30 s: the floor of a step without list builds, our list
walk against a minimal one on the same list, and the builds a partial-rebuild policy would leave.

The questions, declared before the runs:

1. If the list builds cost nothing, what would the bench's run take? Each of its steps would still cost a list walk
   and the passes outside the pair sums (``results/profile_3d_2t.json``): ``steps * (walk + outside)``, plus the
   bench's own time beyond its steps (its wall time less ``steps`` times the profile's mean step).
2. Is our list walk near what a plain numba loop over the same list takes? The minimal walk (timed without the
   sum of its threads' buffers, as ours without its fold) sums Wendland C2's
   ``(1 - q)^3 d`` over the stored half list (sorted points, one buffer per thread, b's terms scattered), which
   is the work of Fan's interior force; it is checked against a brute-force sum on 20 particles. Ours is the
   calculator's ``"pair loop (list walk)"`` of ``benchmarks/profile_fan.py``'s wrappers, on forces-only
   evaluations of slightly moved positions (no rebuild), as the package runs it (in 3D the pair sums give their
   accumulators' pages back after each sum, ``keep_scratch``) and with those pages kept (``ours_kept``, the
   release replaced by nothing: the minimal walk keeps its buffers too). Both on 2 threads, the median of 5.
3. How many builds would a partial-rebuild policy leave? The list stays valid for the pairs of two particles that
   moved less than ``skin / 2`` since the build; the pairs of the others ("fast" particles) could be searched apart
   at every step. On the bench's trajectory at 1e5 (FIRE, every step's positions kept), the builds when a build
   comes only once more than ``f N`` particles are fast, for several ``f``, and the most fast particles a step.
4. (``--whole-runs K``) Does keeping the accumulators' pages shorten the bench's whole 3D run? ``K`` pairs of
   ``bench_fan_1e6.run_ours`` at 1e6, as the package runs it and with the pages kept, alternating in one process.

    NUMBA_NUM_THREADS=2 python reproductions/speed-fan-1e6/walk_floor_3d.py --whole-runs 2 \
        --out reproductions/speed-fan-1e6/results/walk_floor_3d.json
"""
import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numba
import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))

FRACTIONS = (0.0, 1e-4, 1e-3, 3e-3, 1e-2, 3e-2)


@numba.njit(parallel=True, cache=True)
def minimal_walk(x_sc, pair_start, pair_j, h, bufs):
    """Sum of (1 - r/h)^3 (x_b - x_a) over each point's partners within h: the half list walked once, b's terms
    scattered to b, one buffer per thread (summed afterwards)."""
    n = x_sc.shape[0]
    nt = bufs.shape[0]
    inv_h = 1.0 / h
    chunk = (n + nt - 1) // nt
    for t in numba.prange(nt):
        f = bufs[t]
        f[:] = 0.0
        for a in range(t * chunk, min(n, (t + 1) * chunk)):
            xa, ya, za = x_sc[a, 0], x_sc[a, 1], x_sc[a, 2]
            fx = 0.0
            fy = 0.0
            fz = 0.0
            for p in range(pair_start[a], pair_start[a + 1]):
                b = pair_j[p]
                dx = x_sc[b, 0] - xa
                dy = x_sc[b, 1] - ya
                dz = x_sc[b, 2] - za
                tq = max(1.0 - np.sqrt(dx * dx + dy * dy + dz * dz) * inv_h, 0.0)
                g = tq * tq * tq
                fx += g * dx
                fy += g * dy
                fz += g * dz
                f[b, 0] -= g * dx
                f[b, 1] -= g * dy
                f[b, 2] -= g * dz
            f[a, 0] += fx
            f[a, 1] += fy
            f[a, 2] += fz


def walks(n, repeats=5):
    """Question 2: our walk and the minimal one on the stored list of the bench's start at ``n``."""
    from ase.calculators.calculator import all_changes
    from scipy.spatial import cKDTree

    import bench_fan_1e6 as bf
    import profile_fan as pf

    from ase_sphrelax import FanCalculator, make_optimizer, pairs

    pf.instrument()
    bf.warm_up(3)
    domain, dx, atoms = bf.scene(3, n)
    h = bf.RATIO * dx
    calc = atoms.calc = FanCalculator(h=h, dx=dx, domain=domain)
    make_optimizer("fire", atoms).run(fmax=0.0, steps=2)  # a stored list, built and walked
    rng = np.random.default_rng(0)

    def timed_walks():
        times = []
        for _ in range(repeats):
            atoms.positions += rng.uniform(-1e-4, 1e-4, atoms.positions.shape) * calc.skin
            builds = calc.nlist.builds
            pf.TIMES.clear()
            calc.calculate(atoms, ["forces"], all_changes)
            assert calc.nlist.builds == builds, "a rebuild: not a walk"
            times.append(pf.TIMES["pair loop (list walk)"])
        return times

    ours = timed_walks()
    release = pairs.release_scratch
    pairs.release_scratch = lambda: None  # the accumulators' pages kept between sums
    try:
        ours_kept = timed_walks()
    finally:
        pairs.release_scratch = release
    nlist = calc.nlist
    x_sc = np.ascontiguousarray(nlist.extend(atoms.positions))
    pair_start, pair_j = nlist.pair_start, nlist.pair_j
    bufs = np.zeros((numba.get_num_threads(), x_sc.shape[0], 3))
    minimal_walk(x_sc, pair_start, pair_j, h, bufs)  # compile or load
    minimal = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        minimal_walk(x_sc, pair_start, pair_j, h, bufs)
        minimal.append(time.perf_counter() - t0)  # the walk alone, as ours (its fold is another part)
    g_sc = bufs.sum(axis=0)
    # the minimal walk sums what it should: brute force on 20 points
    tree = cKDTree(x_sc)
    worst = 0.0
    for a in rng.integers(0, x_sc.shape[0], 20):
        b = np.array(tree.query_ball_point(x_sc[a], h), dtype=int)
        d = x_sc[b] - x_sc[a]
        g = np.clip(1.0 - np.linalg.norm(d, axis=1) / h, 0.0, None) ** 3
        worst = max(worst, float(np.abs((g[:, None] * d).sum(axis=0) - g_sc[a]).max() / np.abs(g_sc).max()))
    pairs = int(pair_j.shape[0])
    threads = numba.get_num_threads()
    return dict(n=len(atoms), pairs=pairs, pairs_per_point=pairs / len(atoms), threads=threads,
                ours_walk=float(np.median(ours)), ours_walk_times=ours,
                minimal_walk=float(np.median(minimal)), minimal_walk_times=minimal,
                ours_kept=float(np.median(ours_kept)), ours_kept_times=ours_kept,
                ours_over_minimal=float(np.median(ours) / np.median(minimal)),
                ours_kept_over_minimal=float(np.median(ours_kept) / np.median(minimal)),
                ns_per_pair_thread_ours=float(np.median(ours)) * threads / pairs * 1e9,
                ns_per_pair_thread_minimal=float(np.median(minimal)) * threads / pairs * 1e9,
                minimal_vs_brute_force_max_relative=worst)


def partial_rebuilds(n, steps):
    """Question 3: builds of the policy "rebuild once more than f N particles moved more than skin / 2" on the
    bench's FIRE trajectory at ``n``."""
    import bench_fan_1e6 as bf

    from ase_sphrelax import FanCalculator, make_optimizer

    domain, dx, atoms = bf.scene(3, n)
    h = bf.RATIO * dx
    calc = atoms.calc = FanCalculator(h=h, dx=dx, domain=domain)
    opt = make_optimizer("fire", atoms)
    frames = [atoms.positions.copy()]
    opt.attach(lambda: frames.append(atoms.positions.copy()), interval=1)
    opt.run(fmax=0.0, steps=steps)
    half_skin = 0.5 * calc.skin
    x_tpc = np.array(frames)
    rows = []
    for f in FRACTIONS:
        x0 = x_tpc[0]
        builds, most, fast_steps = 1, 0, 0
        for x in x_tpc[1:]:
            fast = int(np.count_nonzero(np.sum((x - x0) ** 2, axis=1) > half_skin**2))
            if fast > f * len(x0):
                x0, builds = x, builds + 1
            else:
                most, fast_steps = max(most, fast), fast_steps + fast
        rows.append(dict(fraction=f, builds=builds, most_fast=most, fast_particle_steps=fast_steps))
    net = np.linalg.norm(x_tpc[-1] - x_tpc[0], axis=1) / half_skin
    path = np.linalg.norm(np.diff(x_tpc, axis=0), axis=2).sum(axis=0) / half_skin
    return dict(n=len(atoms), steps=int(opt.nsteps), package_builds=int(calc.nlist.builds), policies=rows,
                net_displacement_max_half_skins=float(net.max()), path_max_half_skins=float(path.max()))


def whole_runs(n, pairs_of_runs):
    """Question 4: the bench's run to its target, as the package runs it and with the pages kept, alternating."""
    import bench_fan_1e6 as bf

    from ase_sphrelax import pairs

    bf.warm_up(3)
    release = pairs.release_scratch
    rows = []
    for _ in range(pairs_of_runs):
        for kept in (False, True):
            pairs.release_scratch = (lambda: None) if kept else release
            try:
                run = bf.run_ours(3, n, 6e-4, 5, 2000)
            finally:
                pairs.release_scratch = release
            rows.append(dict(kept=kept, wall_time=run["wall_time"], steps=run["steps"],
                             final_measure=run["final_measure"]))
    return dict(n=n, runs=rows,
                default_mean=float(np.mean([r["wall_time"] for r in rows if not r["kept"]])),
                kept_mean=float(np.mean([r["wall_time"] for r in rows if r["kept"]])))


def floor(profile, bench):
    """Question 1, from the profile's per-step parts and the bench's 3D run."""
    d = profile["derived"]
    ours = bench["scenes"]["3D"]["ours"]
    mean_step = profile["wall"] / profile["steps"]
    beyond = ours["wall_time"] - ours["steps"] * mean_step
    free = ours["steps"] * (d["walk_each"] + d["outside_pair_sums_per_step"])
    return dict(steps=ours["steps"], walk_each=d["walk_each"], outside_each=d["outside_pair_sums_per_step"],
                bench_beyond_steps=beyond, free_builds_time=free + beyond, bench_time=ours["wall_time"])


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--n", type=float, default=1e6, help="particles of question 2 (default 1e6)")
    parser.add_argument("--n-partial", type=float, default=1e5, help="particles of question 3 (default 1e5)")
    parser.add_argument("--steps", type=int, default=165, help="FIRE steps of question 3 (default 165: the target)")
    parser.add_argument("--whole-runs", type=int, default=0, help="pairs of whole runs of question 4 (default 0)")
    parser.add_argument("--out", help="JSON file to write")
    args = parser.parse_args(argv)
    here = Path(__file__).resolve().parent
    record = dict(
        floor=floor(json.loads((here / "results" / "profile_3d_2t.json").read_text()),
                    json.loads((ROOT / "benchmarks" / "results" / "bench_fan_1e6.json").read_text())),
        walks=walks(args.n), partial_rebuilds=partial_rebuilds(args.n_partial, args.steps),
        whole_runs=whole_runs(args.n, args.whole_runs) if args.whole_runs else None,
        command="NUMBA_NUM_THREADS=2 python reproductions/speed-fan-1e6/walk_floor_3d.py " + " ".join(sys.argv[1:]),
        load_average=os.getloadavg(),
        version=subprocess.run(["git", "describe", "--always", "--dirty"], capture_output=True, text=True,
                               cwd=ROOT).stdout.strip())
    text = json.dumps(record, indent=1)
    print(text)
    if args.out:
        Path(args.out).write_text(text + "\n")


if __name__ == "__main__":
    main()
