"""One ALARIC force evaluation (H solve included) against a LAMMPS SPH step and a FanCalculator evaluation.

For a jittered periodic lattice (dx = 1, jitter 0.25 dx) of N particles in 2D and 3D, uniform target
(rho* = 1, so the target's own cost is nil), at 1 and 2 threads:

* ``alaric_cold``: first ALARICCalculator forces (H from a global guess, one-shot bins);
* ``alaric_warm``: forces after every particle moved by 1e-3 dx (H from the previous step, Verlet list
  reused): what each step of ALARICDynamics costs, without the viscosity pass;
* ``lammps_step``: a LAMMPS SPH time step, ``pair_style hybrid/overlay sph/rhosum 1 sph/idealgas`` with
  ``fix sph`` (density summation + ideal-gas pressure forces + Monaghan viscosity, neighbour check every
  step), kernel support ``h`` = the mean ALARIC ``H`` (same neighbour count), time per step inside
  ``run 20`` (engine only);
* ``fan_warm``: FanCalculator (h = the same H) forces after the same displacement.

Then the 2D scaling of ``alaric_warm`` from 1e4 to 1e6 (ratio per decade, goal <= 11) and the peak
RSS of a 1e6 2D ALARIC evaluation (a subprocess; goal < 2 GB). Ratios are taken in one run; the load
average is printed and stored.

    .venv/bin/python benchmarks/bench_alaric.py                    # 1e5 2D/3D, scaling, memory
    .venv/bin/python benchmarks/bench_alaric.py --sizes 1e4 --no-scaling --no-memory   # quick

Writes benchmarks/results/bench_alaric.json.
"""
import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import numba
import numpy as np

from ase_sphrelax import ALARICCalculator, FanCalculator
from ase_sphrelax.build import periodic_box


def uniform(x):
    return np.ones(len(x))


def system(n, dim, seed=0):
    side = int(round(n ** (1.0 / dim)))
    return periodic_box((side,) * dim, dx=1.0, dim=dim, lattice="square" if dim == 2 else "cubic", jitter=0.25,
                        seed=seed)


def best_of(fn, repeats=3):
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def time_alaric(atoms, dim):
    calc = ALARICCalculator(target_density=uniform, target_gradient=lambda x: np.zeros_like(x), dim=dim, mass=1.0)
    atoms.calc = calc
    t0 = time.perf_counter()
    atoms.get_forces()
    cold = time.perf_counter() - t0
    rng = np.random.default_rng(1)
    step = {"k": 0}

    def warm():
        delta = np.zeros((len(atoms), 3))
        delta[:, :dim] = rng.uniform(-1e-3, 1e-3, (len(atoms), dim))
        atoms.positions += delta
        atoms.get_forces()
        step["k"] += 1

    warm()  # builds the stored list
    t_warm = best_of(warm)
    neighbours = float(np.mean(calc.state.neighbours_p))
    return dict(cold=cold, warm=t_warm, h_mean=float(np.mean(calc.h_p)), neighbours=neighbours,
                h_iterations=int(calc.state.iterations))


def time_fan(atoms, dim, h):
    atoms.calc = FanCalculator(h=h, dx=1.0, dim=dim)
    atoms.get_forces()
    rng = np.random.default_rng(2)

    def warm():
        delta = np.zeros((len(atoms), 3))
        delta[:, :dim] = rng.uniform(-1e-3, 1e-3, (len(atoms), dim))
        atoms.positions += delta
        atoms.get_forces()

    warm()
    return best_of(warm)


def time_lammps(atoms, dim, h, nthreads):
    import tempfile

    import lammps_io
    from lammps_io._library import new_lammps
    from lammps_io.data_file import write_data

    if not lammps_io.lammps_available():
        return None
    with tempfile.TemporaryDirectory() as tmp:
        box = write_data(atoms, Path(tmp) / "sph.data", atom_style="sph", dim=dim, masses=1.0, rho=1.0, esph=1.0,
                         cv=1.0)
        lmp = new_lammps(nthreads=nthreads)
        cwd = os.getcwd()
        os.chdir(tmp)
        try:
            lmp.commands_list([
                "units lj", f"dimension {box.lammps_dimension}", "boundary p p p", "atom_style sph",
                "atom_modify map array", "read_data sph.data",
                "pair_style hybrid/overlay sph/rhosum 1 sph/idealgas",
                f"pair_coeff * * sph/rhosum {h:.17g}", f"pair_coeff * * sph/idealgas 0.1 {h:.17g}",
                f"neighbor {0.2 * h:.17g} bin", "neigh_modify every 1 delay 0 check yes", "fix s all sph",
                "timestep 1e-4", "thermo 1000", "run 0"])
            lmp.command("run 5 pre no post no")
            runs = []
            for _ in range(3):
                t0 = time.perf_counter()
                lmp.command("run 20 pre no post no")
                runs.append((time.perf_counter() - t0) / 20)
            lmp.close()
        finally:
            os.chdir(cwd)
    return min(runs)


def memory_probe(n):
    """Peak RSS (MB) of a child that builds n 2D particles and evaluates ALARIC forces twice."""
    code = f"""
import resource, numpy as np, sys
sys.path.insert(0, {str(Path(__file__).parent)!r})
from bench_alaric import system, uniform
from ase_sphrelax import ALARICCalculator
atoms = system({n}, 2)
atoms.calc = ALARICCalculator(target_density=uniform, target_gradient=lambda x: np.zeros_like(x), dim=2, mass=1.0)
atoms.get_forces(); atoms.positions[:, :2] += 1e-3; atoms.get_forces()
print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0)
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return float(out.stdout.strip().splitlines()[-1])


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="1e5")
    parser.add_argument("--threads", default="1,2")
    parser.add_argument("--no-scaling", action="store_true")
    parser.add_argument("--no-memory", action="store_true")
    parser.add_argument("--out", default=str(Path(__file__).parent / "results" / "bench_alaric.json"))
    args = parser.parse_args()
    results = dict(load_before=os.getloadavg(), numba_threads_max=numba.config.NUMBA_NUM_THREADS, rows=[])
    print(f"load average {os.getloadavg()}")
    for n in [int(float(s)) for s in args.sizes.split(",")]:
        for dim in (2, 3):
            for nthreads in [int(t) for t in args.threads.split(",")]:
                numba.set_num_threads(min(nthreads, numba.config.NUMBA_NUM_THREADS))
                atoms = system(n, dim)
                al = time_alaric(atoms, dim)
                fan = time_fan(atoms, dim, al["h_mean"])
                lmp = time_lammps(atoms, dim, al["h_mean"], nthreads)
                row = dict(n=len(atoms), dim=dim, threads=nthreads, alaric_cold=al["cold"], alaric_warm=al["warm"],
                           fan_warm=fan, lammps_step=lmp, h_mean=al["h_mean"], neighbours=al["neighbours"],
                           h_iterations=al["h_iterations"],
                           alaric_over_lammps=None if lmp is None else al["warm"] / lmp,
                           alaric_over_fan=al["warm"] / fan)
                results["rows"].append(row)
                lmp_txt = "n/a" if lmp is None else f"{lmp:.4f}"
                ratio_txt = "n/a" if lmp is None else f"{row['alaric_over_lammps']:.2f}"
                print(f"N {len(atoms):8d} {dim}D {nthreads} thr: ALARIC cold {al['cold']:.3f} s warm {al['warm']:.4f} s "
                      f"({al['neighbours']:.0f} neighbours, H iterations {al['h_iterations']}), "
                      f"LAMMPS step {lmp_txt} s, Fan warm {fan:.4f} s; ALARIC/LAMMPS {ratio_txt}, "
                      f"ALARIC/Fan {row['alaric_over_fan']:.2f}", flush=True)
    numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    if not args.no_scaling:
        scaling = []
        for n in (10_000, 100_000, 1_000_000):
            al = time_alaric(system(n, 2), 2)
            scaling.append(dict(n=n, warm=al["warm"], cold=al["cold"]))
            print(f"scaling 2D N {n:8d}: warm {al['warm']:.4f} s cold {al['cold']:.3f} s", flush=True)
        results["scaling_2d"] = scaling
        results["ratio_per_decade"] = [scaling[k + 1]["warm"] / scaling[k]["warm"] for k in range(2)]
        print(f"warm time ratio per decade: {results['ratio_per_decade']}")
    if not args.no_memory:
        rss = memory_probe(1_000_000)
        results["peak_rss_mb_1e6_2d"] = rss
        print(f"peak RSS, 1e6 2D particles, two ALARIC evaluations: {rss:.0f} MB")
    results["load_after"] = os.getloadavg()
    results["self_maxrss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(results, indent=2))
    print(f"load average {os.getloadavg()}; wrote {args.out}")


if __name__ == "__main__":
    main()
