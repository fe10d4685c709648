"""FanCalculator (numba) vs LAMMPS (lammps_io) for Fan's total error: energy + forces.

For each system (jittered square/cubic lattice, h = 2.6 dx, periodic) and 1 or
2 threads (numba threads / LAMMPS OpenMP threads) it times one energy+forces
call of each ASE calculator

* ``rebuild``: positions moved by more than skin/2, so neighbour lists are rebuilt
  (FanCalculator) or LAMMPS does a full ``run 0`` set-up (lammps_io, reuse off);
* ``reuse``: positions moved by 1e-3 dx, neighbour lists reused (FanCalculator
  skin; lammps_io ``reuse_neighbors=True``, one nve/noforce step);

and the bare LAMMPS time per force step inside ``run 20`` (engine only, no
Python transfer).  Optionally a 1e6-particle 2D relaxation end to end
(``lammps_io.run``: data file, LAMMPS FIRE, dump read back).

    python benchmarks/bench_lammps.py                      # N = 1e5, 1e6 in 2D and 3D + 1e6 relaxation
    python benchmarks/bench_lammps.py --sizes 1e5 --no-relax   # quick

Writes benchmarks/results/bench_lammps.json.  Two-thread numbers on a 2-vCPU
machine are only meaningful as ratios taken in the same run.
"""
import argparse
import gc
import json
import math
import os
import platform
import time
from pathlib import Path

import numba
import numpy as np

import lammps_io
from ase_sphrelax import FanCalculator
from ase_sphrelax.build import periodic_box

RATIO = 2.6
DX = 1.0


def system(n_target, dim, seed=0):
    side = int(round(n_target ** (1.0 / dim)))
    lattice = "square" if dim == 2 else "cubic"
    return periodic_box((side,) * dim, dx=DX, dim=dim, lattice=lattice, jitter=0.25, seed=seed)


CPU = {}  # label -> process CPU seconds of the fastest repeat (all threads; robust to other load)


def timed(fn, repeats, label=None):
    """Best wall time of ``repeats`` calls (and its process CPU time in CPU[label])."""
    best = math.inf
    best_cpu = math.inf
    out = None
    for _ in range(repeats):
        c0 = time.process_time()
        t0 = time.perf_counter()
        out = fn()
        wall = time.perf_counter() - t0
        if wall < best:
            best, best_cpu = wall, time.process_time() - c0
    if label is not None:
        CPU[label] = best_cpu
    return best, out


def moves(atoms, dim, seed):
    """Small (1e-3 dx, reuse) and large (0.6 skin > skin/2, rebuild) displacement sets."""
    rng = np.random.default_rng(seed)
    small = np.zeros_like(atoms.positions)
    small[:, :dim] = rng.uniform(-1e-3, 1e-3, (len(atoms), dim)) * DX
    large = np.zeros_like(atoms.positions)
    large[:, 0] = 0.6 * 0.1 * RATIO * DX  # default skin is 0.1 h for both calculators
    return small, large


def bench_calculator(make_calc, atoms, dim, repeats):
    """(first call, rebuild call, reuse call, energy) of one calculator."""
    a = atoms.copy()
    a.calc = make_calc()
    t_first, _ = timed(lambda: (a.get_forces(), a.get_potential_energy()), 1)
    energy = a.get_potential_energy()
    small, large = moves(atoms, dim, 1)

    def call(disp):
        a.positions = a.positions + disp
        return a.get_forces()

    t_rebuild, _ = timed(lambda: call(large), repeats, "rebuild")
    t_reuse, _ = timed(lambda: call(small), repeats, "reuse")
    calc = a.calc
    return a, calc, dict(first=t_first, rebuild=t_rebuild, reuse=t_reuse, energy=energy,
                         rebuild_cpu=CPU["rebuild"], reuse_cpu=CPU["reuse"])


def lammps_engine_step(calc, steps=20):
    """Seconds per MD step of bare LAMMPS (forces with list reuse, v = 0)."""
    lmp = calc._lmp
    lmp.command("velocity all set 0.0 0.0 0.0")
    c0 = time.process_time()
    t0 = time.perf_counter()
    lmp.command(f"run {steps} pre no post no")
    CPU["engine_step"] = (time.process_time() - c0) / steps
    return (time.perf_counter() - t0) / steps


def lammps_setup_run0(calc, repeats):
    lmp = calc._lmp
    return timed(lambda: lmp.command("run 0 post no"), repeats, "engine_run0")[0]


def run_size(n_target, dim, threads, repeats, style):
    atoms = system(n_target, dim)
    h = RATIO * DX
    row = dict(n=len(atoms), dim=dim, h_over_dx=RATIO, style=style, threads={})
    for nt in threads:
        numba.set_num_threads(min(nt, numba.config.NUMBA_NUM_THREADS))
        entry = {}
        _, fan_calc, entry["fan"] = bench_calculator(lambda: FanCalculator(h=h, dx=DX, dim=dim), atoms, dim, repeats)
        del fan_calc
        gc.collect()
        _, calc, entry["lammps"] = bench_calculator(
            lambda: lammps_io.fan_calculator(h, DX, dim, style=style, nthreads=nt), atoms, dim, repeats)
        entry["lammps"]["engine_run0"] = lammps_setup_run0(calc, repeats)
        entry["lammps"]["engine_run0_cpu"] = CPU["engine_run0"]
        calc.close()
        _, calc, entry["lammps_reuse"] = bench_calculator(
            lambda: lammps_io.fan_calculator(h, DX, dim, style=style, nthreads=nt, reuse_neighbors=True),
            atoms, dim, repeats)
        entry["lammps_reuse"]["engine_step"] = lammps_engine_step(calc)
        entry["lammps_reuse"]["engine_step_cpu"] = CPU["engine_step"]
        calc.close()
        gc.collect()
        e_fan = entry["fan"]["energy"]
        entry["energy_rel_diff"] = abs(entry["lammps"]["energy"] - e_fan) / abs(e_fan)
        entry["ratio_rebuild_fan_over_lammps"] = entry["fan"]["rebuild"] / entry["lammps"]["rebuild"]
        entry["ratio_reuse_fan_over_lammps"] = entry["fan"]["reuse"] / entry["lammps_reuse"]["reuse"]
        entry["ratio_cpu_fan_reuse_over_lammps_engine_step"] = (entry["fan"]["reuse_cpu"]
                                                                 / entry["lammps_reuse"]["engine_step_cpu"])
        row["threads"][str(nt)] = entry
        print(f"dim={dim} N={len(atoms):>8d} threads={nt}  "
              f"Fan rebuild {entry['fan']['rebuild']:.3f}s reuse {entry['fan']['reuse']:.3f}s | "
              f"LAMMPS calc rebuild {entry['lammps']['rebuild']:.3f}s reuse {entry['lammps_reuse']['reuse']:.3f}s | "
              f"engine run0 {entry['lammps']['engine_run0']:.3f}s step {entry['lammps_reuse']['engine_step']:.4f}s | "
              f"Fan/LAMMPS rebuild x{entry['ratio_rebuild_fan_over_lammps']:.1f} "
              f"reuse x{entry['ratio_reuse_fan_over_lammps']:.1f} | CPU s: Fan reuse {entry['fan']['reuse_cpu']:.3f} "
              f"LAMMPS step {entry['lammps_reuse']['engine_step_cpu']:.4f} | dE/E {entry['energy_rel_diff']:.1e}",
              flush=True)
    return row


def relax_1e6(steps, nthreads, nprocs):
    atoms = system(1e6, 2, seed=2)
    h = RATIO * DX
    calc = FanCalculator(h=h, dx=DX, dim=2)
    e0 = calc.get_potential_energy(atoms)
    c0 = time.process_time()
    t0 = time.perf_counter()
    relaxed = lammps_io.run(atoms, h, DX, steps=steps, style="table", nthreads=nthreads, nprocs=nprocs)
    wall = time.perf_counter() - t0
    info = relaxed.info["lammps"]
    out = dict(n=len(atoms), steps=steps, nthreads=nthreads, nprocs=nprocs, wall_time_end_to_end=wall,
               cpu_time_end_to_end=time.process_time() - c0, load_average=os.getloadavg(),
               lammps_minimize_wall=info["wall_time"], iterations=info["iterations"], e_start=e0,
               e_final=info["energy"], fnorm_final=info["fnorm"])
    print(f"1e6 2D relaxation: N={len(atoms)} {info['iterations']} FIRE iterations, nthreads={nthreads} "
          f"nprocs={nprocs}: end-to-end {wall:.1f} s wall, {out['cpu_time_end_to_end']:.1f} s CPU "
          f"(LAMMPS part {info['wall_time']:.1f} s wall), "
          f"E {e0:.6g} -> {info['energy']:.6g}", flush=True)
    return out


def main(argv=None):
    parser = argparse.ArgumentParser(description="FanCalculator vs LAMMPS timings")
    parser.add_argument("--sizes", default="1e5,1e6", help="comma separated N (default 1e5,1e6)")
    parser.add_argument("--dims", default="2,3")
    parser.add_argument("--threads", default="1,2")
    parser.add_argument("--style", default="table", choices=["table", "lepton"])
    parser.add_argument("--no-relax", action="store_true", help="skip the 1e6-particle relaxation")
    parser.add_argument("--relax-steps", type=int, default=300)
    parser.add_argument("--out", default=str(Path(__file__).parent / "results" / "bench_lammps.json"))
    args = parser.parse_args(argv)
    sizes = [float(s) for s in args.sizes.split(",")]
    dims = [int(d) for d in args.dims.split(",")]
    threads = [int(t) for t in args.threads.split(",")]
    # warm up numba and LAMMPS on a small system
    small = system(400, 2)
    FanCalculator(h=RATIO * DX, dx=DX, dim=2).get_forces(small)
    lammps_io.fan_calculator(RATIO * DX, DX, 2).get_forces(small)
    results = dict(machine=dict(cpus=os.cpu_count(), python=platform.python_version(),
                                numba_threads=numba.config.NUMBA_NUM_THREADS,
                                load_average_at_start=os.getloadavg()),
                   started=time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()), runs=[])
    for dim in dims:
        for n in sizes:
            results["runs"].append(run_size(n, dim, threads, 2 if n >= 5e5 else 3, args.style))
            gc.collect()
    if not args.no_relax:
        results["relaxation_1e6_2d"] = [relax_1e6(args.relax_steps, nt, 1) for nt in threads]
    results["load_average_at_end"] = os.getloadavg()
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(results, indent=1))
    print(f"wrote {args.out}")
    return results


if __name__ == "__main__":
    main()
