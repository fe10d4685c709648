"""FanCalculator (numba) vs LAMMPS (lammps_io) for Fan's total error: energy + forces (issue 9, item 2).

For each system (jittered square/cubic lattice, h = 2.6 dx, periodic) and 1 or 2
threads (numba threads / LAMMPS OpenMP threads), in interleaved rounds (one of each
measurement per round, so that a change of the machine's load hits all of them):

* ``fan rebuild``: FanCalculator after every particle moved by 0.6 skin: the Verlet list
  is rebuilt (bins, list scan fused with the force pass);
* ``fan warm``: moved by at most 1e-3 dx, list reused: the first evaluation after the
  rebuild, one call (its caches are cold: the rebuild touched other memory);
* ``fan warm steady``: the mean of ``STEADY`` such evaluations in a row (+-1e-3 dx each),
  measured as LAMMPS's ``run 10`` measures its step: the steady state of a relaxation,
  where most steps follow a step that reused the list;
* ``lammps run 0``: the bare engine command ``run 0 post no`` (set-up, neighbour build,
  forces), the reference of ``fan rebuild``;
* ``lammps step``: the bare engine time per MD step inside ``run 10 pre no post no`` with
  v = 0 (forces with the list reused), the reference of ``fan warm``;
* for information, the lammps_io ASE calculator's own calls (``run 0`` through Python,
  and with ``reuse_neighbors=True``), which add the transfer of positions and forces.

Each figure is the median over ``--repeats`` rounds (at least 5). Ratios ours/LAMMPS are
the targets of issue 9: warm / step <= 1, rebuild / run 0 <= 1; both warm figures are
compared with the same LAMMPS step (``steady/step`` is the like-for-like one). Wall time is the figure
(CPU time is printed too; with 2 threads it sums both). The load average is printed
before and after each system: on this shared 2-vCPU machine only same-run ratios mean
anything.

    python benchmarks/bench_lammps.py                       # N = 1e5, 1e6; 2D, 3D; 1, 2 threads
    python benchmarks/bench_lammps.py --sizes 1e5 --repeats 7

Writes benchmarks/results/bench_lammps.json.
"""
import argparse
import gc
import os
import platform
import statistics
import time
from pathlib import Path

import numba
import numpy as np
from ase.calculators.calculator import all_changes

import lammps_io
from ase_sphrelax import FanCalculator
from ase_sphrelax.build import periodic_box

try:
    from _provenance import git_version, write_json
except ImportError:  # run as a module
    from benchmarks._provenance import git_version, write_json

RATIO = 2.6
DX = 1.0
STEADY = 10  # warm evaluations in a row, as LAMMPS's run 10


def system(n_target, dim, seed=0):
    side = int(round(n_target ** (1.0 / dim)))
    lattice = "square" if dim == 2 else "cubic"
    return periodic_box((side,) * dim, dx=DX, dim=dim, lattice=lattice, jitter=0.25, seed=seed)


def clocked(fn):
    """(wall, CPU) seconds of one call."""
    c0 = time.process_time()
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0, time.process_time() - c0


def run_size(n_target, dim, nthreads, repeats, style):
    atoms = system(n_target, dim)
    n = len(atoms)
    h = RATIO * DX
    skin = 0.1 * h  # the default of both calculators
    numba.set_num_threads(min(nthreads, numba.config.NUMBA_NUM_THREADS))
    load_before = os.getloadavg()
    rng = np.random.default_rng(1)

    fan_atoms = atoms.copy()
    fan = FanCalculator(h=h, dx=DX, dim=dim)
    for _ in range(2):  # first call: one-shot scan; second: the list is built
        fan.calculate(fan_atoms, ["energy", "forces"], all_changes)
    e_fan = fan.results["energy"]
    f_fan = fan.results["forces"].copy()

    lmp_calc = lammps_io.fan_calculator(h, DX, dim, style=style, nthreads=nthreads)
    lmp_atoms = atoms.copy()
    lmp_atoms.calc = lmp_calc
    f_lmp = lmp_atoms.get_forces().copy()
    e_lmp = lmp_atoms.get_potential_energy()
    reuse_calc = lammps_io.fan_calculator(h, DX, dim, style=style, nthreads=nthreads, reuse_neighbors=True)
    reuse_atoms = atoms.copy()
    reuse_atoms.calc = reuse_calc
    reuse_atoms.get_forces()
    engine = lmp_calc._lmp
    engine_reuse = reuse_calc._lmp

    def fan_call(disp):
        fan_atoms.positions = fan_atoms.positions + disp
        fan.calculate(fan_atoms, ["energy", "forces"], all_changes)

    large = np.zeros_like(atoms.positions)
    large[:, 0] = 0.6 * skin
    times = {k: [] for k in ("fan_rebuild", "fan_warm", "fan_warm_steady", "lammps_run0", "lammps_step",
                             "lammps_calc_run0", "lammps_calc_reuse")}
    cpu = {k: [] for k in times}
    steps = 10
    for _ in range(repeats):
        builds = fan.nlist.builds
        w, c = clocked(lambda: fan_call(large))
        assert fan.nlist.builds == builds + 1, "the rebuild call did not rebuild"
        times["fan_rebuild"].append(w)
        cpu["fan_rebuild"].append(c)
        small = np.zeros_like(atoms.positions)
        small[:, :dim] = rng.uniform(-1e-3, 1e-3, (n, dim)) * DX
        w, c = clocked(lambda: fan_call(small))
        assert fan.nlist.builds == builds + 1, "the warm call rebuilt the list"
        times["fan_warm"].append(w)
        cpu["fan_warm"].append(c)

        def steady():
            for k in range(STEADY):
                fan_call(-small if k % 2 == 0 else small)
        w, c = clocked(steady)
        assert fan.nlist.builds == builds + 1, "a steady warm call rebuilt the list"
        times["fan_warm_steady"].append(w / STEADY)
        cpu["fan_warm_steady"].append(c / STEADY)
        w, c = clocked(lambda: engine.command("run 0 post no"))
        times["lammps_run0"].append(w)
        cpu["lammps_run0"].append(c)
        engine_reuse.command("velocity all set 0.0 0.0 0.0")  # the calculator's reuse calls set v
        w, c = clocked(lambda: engine_reuse.command(f"run {steps} pre no post no"))
        times["lammps_step"].append(w / steps)
        cpu["lammps_step"].append(c / steps)
        lmp_atoms.positions = lmp_atoms.positions + large
        w, c = clocked(lambda: lmp_atoms.get_forces())
        times["lammps_calc_run0"].append(w)
        cpu["lammps_calc_run0"].append(c)
        reuse_atoms.positions = reuse_atoms.positions + small
        w, c = clocked(lambda: reuse_atoms.get_forces())
        times["lammps_calc_reuse"].append(w)
        cpu["lammps_calc_reuse"].append(c)
    lmp_calc.close()
    reuse_calc.close()
    med = {k: statistics.median(v) for k, v in times.items()}
    med_cpu = {k: statistics.median(v) for k, v in cpu.items()}
    row = dict(n=n, dim=dim, threads=nthreads, h_over_dx=RATIO, style=style, repeats=repeats,
               wall=med, cpu=med_cpu, wall_all=times,
               ratio_warm_over_step=med["fan_warm"] / med["lammps_step"],
               ratio_steady_over_step=med["fan_warm_steady"] / med["lammps_step"],
               ratio_cpu_steady_over_step=med_cpu["fan_warm_steady"] / med_cpu["lammps_step"],
               ratio_rebuild_over_run0=med["fan_rebuild"] / med["lammps_run0"],
               ratio_cpu_warm_over_step=med_cpu["fan_warm"] / med_cpu["lammps_step"],
               ratio_cpu_rebuild_over_run0=med_cpu["fan_rebuild"] / med_cpu["lammps_run0"],
               energy_rel_diff=abs(e_lmp - e_fan) / abs(e_fan),
               force_max_diff_over_max=float(np.abs(f_lmp - f_fan).max() / np.abs(f_fan).max()),
               load_before=load_before, load_after=os.getloadavg())
    print(f"{dim}D N={n:>8d} threads={nthreads} (median of {repeats}, ms) "
          f"fan rebuild {1e3 * med['fan_rebuild']:.1f} warm {1e3 * med['fan_warm']:.2f} "
          f"steady {1e3 * med['fan_warm_steady']:.2f} | "
          f"LAMMPS run0 {1e3 * med['lammps_run0']:.1f} step {1e3 * med['lammps_step']:.2f} | "
          f"ratios warm/step {row['ratio_warm_over_step']:.2f} steady/step {row['ratio_steady_over_step']:.2f} "
          f"rebuild/run0 {row['ratio_rebuild_over_run0']:.2f} (CPU {row['ratio_cpu_warm_over_step']:.2f} "
          f"{row['ratio_cpu_steady_over_step']:.2f} {row['ratio_cpu_rebuild_over_run0']:.2f}) | "
          f"lammps_io calc run0 {1e3 * med['lammps_calc_run0']:.1f} reuse {1e3 * med['lammps_calc_reuse']:.1f} | "
          f"dE/E {row['energy_rel_diff']:.1e} | load {load_before[0]:.2f} -> {row['load_after'][0]:.2f}",
          flush=True)
    return row


def main(argv=None):
    parser = argparse.ArgumentParser(description="FanCalculator vs LAMMPS timings")
    parser.add_argument("--sizes", default="1e5,1e6", help="comma separated N (default 1e5,1e6)")
    parser.add_argument("--dims", default="2,3")
    parser.add_argument("--threads", default="1,2")
    parser.add_argument("--style", default="table", choices=["table", "lepton"])
    parser.add_argument("--repeats", type=int, default=7, help="interleaved rounds (>= 5)")
    parser.add_argument("--out", default=str(Path(__file__).parent / "results" / "bench_lammps.json"))
    args = parser.parse_args(argv)
    if args.repeats < 5:
        parser.error("--repeats must be at least 5")
    sizes = [float(s) for s in args.sizes.split(",")]
    dims = [int(d) for d in args.dims.split(",")]
    threads = [int(t) for t in args.threads.split(",")]
    # compile / load numba and LAMMPS outside the timings
    small = system(400, 2)
    FanCalculator(h=RATIO * DX, dx=DX, dim=2).get_forces(small)
    lammps_io.fan_calculator(RATIO * DX, DX, 2).get_forces(small)
    print(f"load average {os.getloadavg()}", flush=True)
    results = dict(version=git_version(),
                   machine=dict(cpus=os.cpu_count(), python=platform.python_version(),
                                numba_threads=numba.config.NUMBA_NUM_THREADS),
                   started=time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
                   load_average_at_start=os.getloadavg(), runs=[])
    for dim in dims:
        for n in sizes:
            for nt in threads:
                results["runs"].append(run_size(n, dim, nt, args.repeats, args.style))
                gc.collect()
    results["load_average_at_end"] = os.getloadavg()
    print(f"load average {os.getloadavg()}")
    write_json(args.out, results)
    return results


if __name__ == "__main__":
    main()
