"""BISPH (boundary-integral walls) vs LAMMPS ``sph/taitwater`` (wall particles): one step (issue 29, item 1).

The same fluid: a rectangular tank at rest under gravity, ``dx = 0.01`` m, water ``D`` deep in a tank
``W`` wide (``--n`` fluid particles on BIPI2D's Cartesian start, hydrostatic densities), support
``h = 4 dx`` for both (BISPH: Wendland C2 with the paper's ``h_B = 2 dx``; LAMMPS: Lucy's kernel of
support ``h``).

* ``bisph step``: :meth:`ase_sphrelax.flows.bisph.BISPH.step` with a fixed ``dt``: neighbour-list check
  (and rebuild when due), the boundary integrals (gamma, grad gamma of the particles within ``h`` of a
  wall), Eq. 17's pair pass, Eq. 16's pair pass, the wall terms, the symplectic Euler update;
* ``lammps step``: the engine time per step inside ``run K pre no post no`` of ``pair_style
  sph/taitwater`` (continuity density, as ``lammps_io.hydrostatic_tank``), ``fix sph`` on the fluid,
  ``fix sph/stationary`` on the wall particles (the grid continued outside the walls, ``h`` thick:
  the Step-1 grid walls), ``fix gravity``, the same ``dt``.

Both in interleaved rounds (one of each per round, so that a change of the machine's load hits both);
each figure is the median over ``--repeats`` rounds; ratio = bisph / lammps, on 1 and 2 threads (numba
threads; LAMMPS ``-sf omp -pk omp N``: the SPH package has no OpenMP styles, so LAMMPS runs its serial
``sph/taitwater`` whatever N, which the JSON records as ``lammps_omp_styles``). The load average is
printed before and after each thread count: on this shared 2-vCPU machine only same-run ratios mean
anything.

    python benchmarks/bench_bisph_lammps.py                 # 1e5 fluid particles, 1 and 2 threads
    python benchmarks/bench_bisph_lammps.py --n 2e4 --repeats 5

Writes benchmarks/results/bench_bisph_lammps.json. Target (issue 29): ratio <= 3 on 1 and 2 threads.
"""
import argparse
import math
import os
import platform
import statistics
import tempfile
import time
from pathlib import Path

import numba
import numpy as np
from ase import Atoms

import lammps_io
from lammps_io._library import new_lammps
from lammps_io.data_file import write_data
from lammps_io.sph_flows import FLUID, WALL
from ase_sphrelax.boundary import BoundarySegments
from ase_sphrelax.flows.scene import cartesian_fill, tank

try:
    from _provenance import git_version, write_json
except ImportError:  # run as a module
    from benchmarks._provenance import git_version, write_json

DX = 0.01
H_OVER_DX = 4.0
RHO0 = 1000.0
G = 9.81


def scene(n_target):
    """The tank (width = depth / 1.1), its fluid, and the grid wall particles (h thick, outside)."""
    side = math.sqrt(n_target / 1.1)
    nx = int(round(side))
    ny = int(round(1.1 * side))
    width, depth = nx * DX, ny * DX
    walls = BoundarySegments.from_vertices([[0, 0], [width, 0], [width, 1.3 * depth], [0, 1.3 * depth]])
    fluid = cartesian_fill(walls, DX, depth)
    layers = int(round(H_OVER_DX))
    gx, gy = np.meshgrid(DX * (np.arange(-layers, nx + layers) + 0.5), DX * (np.arange(-layers, ny) + 0.5))
    grid = np.column_stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)])
    outside = (grid[:, 0] < 0) | (grid[:, 0] > width) | (grid[:, 1] < 0)
    return walls, fluid, grid[outside], width, depth


def lammps_engine(fluid, wall, depth, c0, dt, nthreads, folder):
    """A LAMMPS instance set up on the tank (``lammps_io.hydrostatic_tank``'s model, alpha = 0)."""
    h = H_OVER_DX * DX
    positions = np.vstack([fluid, wall])
    atoms = Atoms("H" * len(positions), positions=positions)
    atoms.arrays["type"] = np.array([FLUID] * len(fluid) + [WALL] * len(wall))
    rho = RHO0 * (1.0 + RHO0 * G * np.maximum(depth - positions[:, 1], 0.0) / (RHO0 * c0 * c0))
    box = write_data(atoms, Path(folder) / "tank.data", atom_style="sph", dim=2, masses=[RHO0 * DX**2] * 2,
                     rho=rho, esph=0.0, cv=1.0, margin=4.0 * h)
    lmp = new_lammps(nthreads=nthreads)
    cwd = os.getcwd()
    os.chdir(folder)
    try:
        lmp.commands_list([
            *box.read_data_commands("tank.data", "sph", "s s p", units="si"),
            "pair_style sph/taitwater",
            f"pair_coeff * * {RHO0:.17g} {c0:.17g} 0.0 {h:.17g}",
            f"group fluid type {FLUID}", f"group wall type {WALL}",
            f"neighbor {0.5 * DX:.17g} bin", "neigh_modify every 1 delay 0 check yes",
            "fix flowsph fluid sph", "fix flowwall wall sph/stationary",
            f"fix flowgrav fluid gravity {G:.17g} vector 0 -1 0", "fix flow2d all enforce2d",
            f"timestep {dt:.17g}", "thermo 0", "run 0"])
    finally:
        os.chdir(cwd)
    return lmp


def omp_styles(lmp):
    try:
        return sorted(s for s in lmp.available_styles("pair") if s.startswith("sph/") and s.endswith("/omp"))
    except Exception:  # noqa: BLE001 - older Python modules have no available_styles
        return None


def clocked(fn):
    c0 = time.process_time()
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0, time.process_time() - c0


def run_threads(walls, fluid, wall, depth, nthreads, repeats, steps, folder):
    numba.set_num_threads(min(nthreads, numba.config.NUMBA_NUM_THREADS))
    load_before = os.getloadavg()
    sim = tank(walls, fluid, DX, depth)
    dt = sim.time_step()
    for _ in range(3):  # compile, build the lists
        sim.step(dt)
    lmp = lammps_engine(fluid, wall, depth, sim.c0, dt, nthreads, folder)
    lmp.command(f"run {steps} pre no post no")
    times = dict(bisph=[], lammps=[])
    cpu = dict(bisph=[], lammps=[])

    def ours():
        for _ in range(steps):
            sim.step(dt)
    for _ in range(repeats):
        w, c = clocked(ours)
        times["bisph"].append(w / steps)
        cpu["bisph"].append(c / steps)
        w, c = clocked(lambda: lmp.command(f"run {steps} pre no post no"))
        times["lammps"].append(w / steps)
        cpu["lammps"].append(c / steps)
    styles = omp_styles(lmp)
    lmp.close()
    med = {k: statistics.median(v) for k, v in times.items()}
    med_cpu = {k: statistics.median(v) for k, v in cpu.items()}
    row = dict(threads=nthreads, n_fluid=len(fluid), n_wall_particles=len(wall), n_segments=len(walls),
               dt=dt, steps_per_round=steps, repeats=repeats, wall=med, cpu=med_cpu, wall_all=times,
               ratio=med["bisph"] / med["lammps"], ratio_cpu=med_cpu["bisph"] / med_cpu["lammps"],
               lammps_omp_styles=styles, bisph_list_builds=int(sim.nlist.builds),
               load_before=load_before, load_after=os.getloadavg())
    print(f"threads={nthreads} N_fluid={len(fluid)} (+{len(wall)} LAMMPS wall particles; median of {repeats} "
          f"rounds of {steps} steps, ms/step) bisph {1e3 * med['bisph']:.1f} lammps {1e3 * med['lammps']:.1f} "
          f"ratio {row['ratio']:.2f} (CPU {row['ratio_cpu']:.2f}) | load {load_before[0]:.2f} -> "
          f"{row['load_after'][0]:.2f}", flush=True)
    return row


def main(argv=None):
    parser = argparse.ArgumentParser(description="BISPH vs LAMMPS sph/taitwater: time per step")
    parser.add_argument("--n", type=float, default=1e5, help="fluid particles (default 1e5)")
    parser.add_argument("--threads", default="1,2")
    parser.add_argument("--repeats", type=int, default=5, help="interleaved rounds (>= 3)")
    parser.add_argument("--steps", type=int, default=5, help="steps per round")
    parser.add_argument("--out", default=str(Path(__file__).parent / "results" / "bench_bisph_lammps.json"))
    args = parser.parse_args(argv)
    if args.repeats < 3:
        parser.error("--repeats must be at least 3")
    lammps_io.import_lammps() if hasattr(lammps_io, "import_lammps") else None
    walls, fluid, wall, width, depth = scene(args.n)
    print(f"tank {width:.2f} x {depth:.2f} m (water), {len(fluid)} fluid particles; load average "
          f"{os.getloadavg()}", flush=True)
    results = dict(version=git_version(),
                   machine=dict(cpus=os.cpu_count(), python=platform.python_version(),
                                numba_threads=numba.config.NUMBA_NUM_THREADS),
                   started=time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
                   dx=DX, h_over_dx=H_OVER_DX, tank=dict(width=width, depth=depth),
                   load_average_at_start=os.getloadavg(), target_ratio=3.0, runs=[])
    with tempfile.TemporaryDirectory(prefix="bench_bisph_") as folder:
        for nt in [int(t) for t in args.threads.split(",")]:
            results["runs"].append(run_threads(walls, fluid, wall, depth, nt, args.repeats, args.steps, folder))
    results["load_average_at_end"] = os.getloadavg()
    results["met"] = all(r["ratio"] <= 3.0 for r in results["runs"])
    print(f"load average {os.getloadavg()}; ratio <= 3 on every thread count: {results['met']}")
    write_json(args.out, results)
    return results


if __name__ == "__main__":
    main()
