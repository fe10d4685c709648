"""One ALARIC force evaluation (H solve included) against a LAMMPS SPH step and a FanCalculator evaluation.

For a jittered periodic lattice (dx = 1, jitter 0.25 dx) of N particles in 2D and 3D, uniform target
(rho* = 1, so the target's own cost is nil), at 1 and 2 threads, in interleaved rounds (one of each
measurement per round, so that a change of the machine's load hits all three):

* ``alaric``: ALARICCalculator forces after every particle moved by up to 1e-3 dx (H from the previous
  step, Verlet list reused): what each step of ALARICDynamics costs, without the viscosity pass; the
  median of ``--repeats`` such calls;
* ``fan``: FanCalculator (h = the mean ALARIC H) forces after the same kind of move, median of ``--repeats``;
* ``lammps``: a LAMMPS SPH time step, ``pair_style hybrid/overlay sph/rhosum 1 sph/idealgas`` with
  ``fix sph`` (density summation + ideal-gas pressure forces + Monaghan viscosity, neighbour check every
  step), kernel support ``h`` = the mean ALARIC ``H`` (same neighbour count), time per step inside
  ``run 20`` (engine only).

Each figure is the median over ``--rounds`` rounds, wall and CPU (process) time; the ratios are the medians
of the per-round ratios. On one thread CPU time is the robust figure on this shared machine (it leaves out
the time slices of other processes); on two threads wall time is the figure.

``--profile``: where one ALARIC evaluation's time goes (1 thread, CPU time, median over the rounds): the
smoothing-length solve's density passes (how many, and their time), its per-particle H update, the force
pass, the neighbour-list check and the rest (target, energies, Python).

Scaling (``--scaling-sizes``, default 1e4, 1e5, 3e5): the warm evaluation's CPU time per particle on one
thread in 2D and 3D, the sizes interleaved in each round (goal: flat). ``--memory``: peak RSS of a 1e6 2D
ALARIC evaluation (a subprocess; goal < 2 GB).

    .venv/bin/python benchmarks/bench_alaric.py --profile                 # 1e5 2D/3D, 1/2 threads, scaling
    .venv/bin/python benchmarks/bench_alaric.py --sizes 1e4 --no-scaling --rounds 3   # quick

Writes benchmarks/results/bench_alaric.json (``--out``).

``--ab-baseline CHECKOUT``: only a before/after comparison: the warm evaluation above (1e5 or the first of
``--sizes``, 1 thread, CPU time, median of 9 calls per process) of this checkout and of ``CHECKOUT`` (a folder
holding a baseline's ``ase_sphrelax``, e.g. ``git archive main | tar -x -C /tmp/base``), one fresh process per
checkout and round, the order alternating, ``--ab-rounds`` rounds per dimension of ``--dims``; medians and the
median of the per-round ratios, and whether the forces and H are the same bit for bit.

``--dynamics``: a controlled timing of ALARICDynamics instead (the warm evaluation above reuses its Verlet list;
the dynamics rebuild it whenever H or the moves outgrow the skin). The same relaxation (2D uniform density in the
unit circle, ``--dyn-n`` particles from one uniformly random start, ``--dyn-steps`` steps, the default ingredients
S+F+V, no convergence stop, ``--dyn-boundary`` wall or mirror) for each skin factor of ``--dyn-factors`` (skin =
factor x the mean H at the first evaluation, i.e. ``calculators.alaric.SKIN_FACTOR`` replaced in the child), each
run in a fresh process on one thread, the factors alternating in ``--dyn-rounds`` rounds after one untimed warm-up
process per factor (numba's cache); medians of wall and CPU time of ``dyn.run`` (the first evaluation included,
a 300-particle warm-up run in the same process before it), list builds, evaluations and the final epsilon:

    nice -n 10 .venv/bin/python benchmarks/bench_alaric.py --dynamics --dyn-n 10000 --dyn-steps 300 \
        --dyn-rounds 5 --dyn-factors 0.1,0.2 --dyn-boundary wall --out benchmarks/results/bench_alaric_dynamics_skin.json
"""
import argparse
import functools
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numba
import numpy as np

from ase_sphrelax import ALARICCalculator, FanCalculator, sph
from ase_sphrelax.build import periodic_box
from ase_sphrelax.neighbors import NeighborList

try:
    from _provenance import git_version, write_json
except ImportError:  # run as a module
    from benchmarks._provenance import git_version, write_json

STEP = 1e-3  # largest move per coordinate between evaluations (dx = 1)


def uniform(x):
    return np.ones(len(x))


def no_gradient(x):
    return np.zeros_like(x)


def system(n, dim, seed=0):
    side = int(round(n ** (1.0 / dim)))
    return periodic_box((side,) * dim, dx=1.0, dim=dim, lattice="square" if dim == 2 else "cubic", jitter=0.25,
                        seed=seed)


def clocked(fn):
    """(wall, CPU) seconds of one call."""
    c0 = time.process_time()
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0, time.process_time() - c0


def median_of(fn, repeats):
    """(wall, CPU): the medians over ``repeats`` calls."""
    times = [clocked(fn) for _ in range(repeats)]
    return statistics.median(t[0] for t in times), statistics.median(t[1] for t in times)


class Mover:
    """Forces of ``atoms`` after a random move of every particle by up to STEP per coordinate."""

    def __init__(self, atoms, dim, seed):
        self.atoms, self.dim = atoms, dim
        self.rng = np.random.default_rng(seed)

    def __call__(self):
        delta = np.zeros((len(self.atoms), 3))
        delta[:, : self.dim] = self.rng.uniform(-STEP, STEP, (len(self.atoms), self.dim))
        self.atoms.positions += delta
        self.atoms.get_forces()


def alaric_case(n, dim):
    """(mover, calculator) of a warm ALARIC evaluation: three evaluations done (the second stores the list, the
    third walks it: every loop compiled or loaded from numba's cache)."""
    atoms = system(n, dim)
    calc = ALARICCalculator(target_density=uniform, target_gradient=no_gradient, dim=dim, mass=1.0, form="log")
    atoms.calc = calc
    atoms.get_forces()
    move = Mover(atoms, dim, seed=1)
    move()
    move()
    return move, calc


def fan_case(n, dim, h):
    atoms = system(n, dim)
    atoms.calc = FanCalculator(h=h, dx=1.0, dim=dim)
    atoms.get_forces()
    move = Mover(atoms, dim, seed=2)
    move()
    move()
    return move


class LammpsStep:
    """A LAMMPS SPH run kept open; calling it times ``run 20`` and returns the time per step."""

    def __init__(self, n, dim, h, nthreads):
        from lammps_io._library import new_lammps
        from lammps_io.data_file import write_data

        self.tmp = tempfile.TemporaryDirectory()
        atoms = system(n, dim)
        box = write_data(atoms, Path(self.tmp.name) / "sph.data", atom_style="sph", dim=dim, masses=1.0, rho=1.0,
                         esph=1.0, cv=1.0)
        self.lmp = new_lammps(nthreads=nthreads)
        cwd = os.getcwd()
        os.chdir(self.tmp.name)
        try:
            self.lmp.commands_list([
                "units lj", f"dimension {box.lammps_dimension}", "boundary p p p", "atom_style sph",
                "atom_modify map array", "read_data sph.data",
                "pair_style hybrid/overlay sph/rhosum 1 sph/idealgas",
                f"pair_coeff * * sph/rhosum {h:.17g}", f"pair_coeff * * sph/idealgas 0.1 {h:.17g}",
                f"neighbor {0.2 * h:.17g} bin", "neigh_modify every 1 delay 0 check yes", "fix s all sph",
                "timestep 1e-4", "thermo 1000", "run 0"])
            self.lmp.command("run 5 pre no post no")
        finally:
            os.chdir(cwd)

    def __call__(self):
        self.lmp.command("run 20 pre no post no")

    def close(self):
        self.lmp.close()
        self.tmp.cleanup()


def lammps_available():
    try:
        import lammps_io

        return lammps_io.lammps_available()
    except ImportError:
        return False


def compare(n, dim, nthreads, rounds, repeats, with_lammps):
    """Interleaved rounds of ALARIC, Fan and LAMMPS at one size, dimension and thread count."""
    numba.set_num_threads(min(nthreads, numba.config.NUMBA_NUM_THREADS))
    load_before = os.getloadavg()
    alaric, calc = alaric_case(n, dim)
    h_mean = float(np.mean(calc.h_p))
    fan = fan_case(n, dim, h_mean)
    lammps = LammpsStep(n, dim, h_mean, nthreads) if with_lammps else None
    per_round = []
    for _ in range(rounds):
        entry = dict(alaric=median_of(alaric, repeats), fan=median_of(fan, repeats))
        if lammps is not None:
            wall, cpu = clocked(lammps)
            entry["lammps"] = (wall / 20, cpu / 20)
        per_round.append(entry)
    if lammps is not None:
        lammps.close()
    row = dict(n=len(calc.h_p), dim=dim, threads=nthreads, h_mean=h_mean,
               neighbours=float(np.mean(calc.state.neighbours_p)), h_passes=int(calc.state.iterations),
               load_before=load_before, load_after=os.getloadavg(), rounds=per_round)
    names = ["alaric", "fan"] + (["lammps"] if lammps is not None else [])
    for k, clock in enumerate(("wall", "cpu")):
        for name in names:
            row[f"{name}_{clock}"] = statistics.median(r[name][k] for r in per_round)
        row[f"alaric_over_fan_{clock}"] = statistics.median(r["alaric"][k] / r["fan"][k] for r in per_round)
        if lammps is not None:
            row[f"alaric_over_lammps_{clock}"] = statistics.median(r["alaric"][k] / r["lammps"][k]
                                                                  for r in per_round)
    return row


# -- profile: the parts of one evaluation --------------------------------------------------------------------
# the H solve's density pass: _solve_pass since issue 20's 2D speed work (its moments are formed in the H update),
# _solve_sums before (a baseline checkout)
_PARTS = (("solve pass", sph, "_solve_pass" if hasattr(sph, "_solve_pass") else "_solve_sums"),
          ("H update", sph, "_smoothing_length_step"),
          ("H solve", sph, "solve_smoothing_lengths"), ("force pass", sph, "pressure_forces"),
          ("neighbour check", NeighborList, "update"))


def profile(n, dim, rounds, repeats):
    """CPU time per part of a warm evaluation on one thread (medians over rounds x repeats evaluations)."""
    numba.set_num_threads(1)
    move, calc = alaric_case(n, dim)
    spent = {}
    originals = []
    for label, owner, name in _PARTS:
        original = getattr(owner, name)
        originals.append((owner, name, original))

        def timed(*args, _original=original, _label=label, **kwargs):
            c0 = time.process_time()
            try:
                return _original(*args, **kwargs)
            finally:
                spent[_label] = spent.get(_label, 0.0) + time.process_time() - c0

        setattr(owner, name, functools.wraps(original)(timed))
    samples = []
    try:
        for _ in range(rounds * repeats):
            spent.clear()
            _, cpu = clocked(move)
            samples.append(dict(spent, total=cpu, passes=calc.state.iterations))
    finally:
        for owner, name, original in originals:
            setattr(owner, name, original)
    out = {key: statistics.median(s.get(key, 0.0) for s in samples) for key in samples[0]}
    # the list is checked twice: by the calculator's prepare and in the H solve (counted in both)
    out["H solve, other (list check, numpy)"] = out["H solve"] - out["solve pass"] - out["H update"]
    out["rest (target, energies, ASE, Python)"] = out["total"] - out["H solve"] - out["force pass"]
    return dict(n=len(calc.h_p), dim=dim, parts=out, load=os.getloadavg())


def scaling(dim, sizes, rounds, repeats):
    """CPU time per particle of a warm evaluation on one thread, the sizes interleaved in each round."""
    numba.set_num_threads(1)
    cases = [alaric_case(n, dim) for n in sizes]
    per_round = [[median_of(move, repeats)[1] / len(calc.h_p) for move, calc in cases] for _ in range(rounds)]
    per_particle = [statistics.median(r[k] for r in per_round) for k in range(len(sizes))]
    return dict(dim=dim, n=[len(calc.h_p) for _, calc in cases], cpu_per_particle=per_particle,
                relative_to_smallest=[p / per_particle[0] for p in per_particle], rounds=per_round)


def memory_probe(n):
    """Peak RSS (MB) of a child that builds n 2D particles and evaluates ALARIC forces twice."""
    code = f"""
import resource, numpy as np, sys
sys.path.insert(0, {str(Path(__file__).parent)!r})
from bench_alaric import system, uniform, no_gradient
from ase_sphrelax import ALARICCalculator
atoms = system({n}, 2)
atoms.calc = ALARICCalculator(target_density=uniform, target_gradient=no_gradient, dim=2, mass=1.0, form="log")
atoms.get_forces(); atoms.positions[:, :2] += 1e-3; atoms.get_forces()
print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0)
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return float(out.stdout.strip().splitlines()[-1])


# -- A/B: this checkout against a baseline, warm evaluations in fresh processes --------------------------------
def ab_child(dim, n):
    """One warm evaluation's CPU time in this process (a fresh child, 1 thread): the median of 9 calls after
    :func:`alaric_case`, and digests of the last call's forces and H (equal digests: the same results bit for bit)."""
    import hashlib

    numba.set_num_threads(1)
    move, calc = alaric_case(n, dim)
    cpu = [clocked(move)[1] for _ in range(9)]
    res = calc.results
    digest = {key: hashlib.sha1(np.ascontiguousarray(res[key]).tobytes()).hexdigest()[:12]
              for key in ("forces", "smoothing_lengths")}
    return dict(dim=dim, n=len(calc.h_p), cpu_s=statistics.median(cpu), energy=float(res["energy"]), digest=digest,
                load=os.getloadavg()[0])


def ab_comparison(baseline, dims, n, rounds):
    """``rounds`` rounds of one fresh one-thread process per checkout (this one and ``baseline``, the order
    alternating), per dimension; medians of the CPU times and of the per-round ratios this / baseline."""
    here = str(Path(__file__).resolve().parents[1])
    env = dict(os.environ, OMP_NUM_THREADS="1", NUMBA_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")

    def child(root, dim):
        code = (f"import sys, json; sys.path.insert(0, {str(Path(__file__).parent)!r}); "
                f"import ase_sphrelax; print(ase_sphrelax.__file__); "
                f"from bench_alaric import ab_child; print(json.dumps(ab_child({dim}, {n})))")
        # cwd = the checkout: "python -c" puts the working directory first on sys.path
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                             env=dict(env, PYTHONPATH=root), cwd=root)
        row = json.loads(out.stdout.strip().splitlines()[-1])
        row["measured"] = out.stdout.strip().splitlines()[0]
        return row

    rows = []
    for dim in dims:
        for root in (here, baseline):  # untimed: numba's cache filled or loaded
            child(root, dim)
        runs = {"this": [], "baseline": []}
        for k in range(rounds):
            order = [("this", here), ("baseline", baseline)]
            for name, root in (order if k % 2 == 0 else order[::-1]):
                runs[name].append(child(root, dim))
            print(f"{dim}D round {k}: this {1e3 * runs['this'][-1]['cpu_s']:.1f} ms, baseline "
                  f"{1e3 * runs['baseline'][-1]['cpu_s']:.1f} ms CPU, load {runs['this'][-1]['load']:.1f}", flush=True)
        ratios = [a["cpu_s"] / b["cpu_s"] for a, b in zip(runs["this"], runs["baseline"])]
        rows.append(dict(dim=dim, n=runs["this"][0]["n"], this_cpu_s=statistics.median(r["cpu_s"] for r in runs["this"]),
                         baseline_cpu_s=statistics.median(r["cpu_s"] for r in runs["baseline"]),
                         this_over_baseline=statistics.median(ratios), per_round=ratios,
                         same_digests=runs["this"][0]["digest"] == runs["baseline"][0]["digest"], runs=runs))
    return dict(baseline=str(baseline), this=here, rows=rows)


# -- dynamics: the skin in ALARICDynamics, fresh processes ---------------------------------------------------
def dynamics_child(n, steps, factor, boundary, seed):
    """One timed ALARICDynamics run in this process (called in a fresh child): a dict of its figures."""
    import ase_sphrelax.calculators.alaric as calc_module
    from ase_sphrelax.domains import Circle
    from ase_sphrelax.drivers.alaric_dynamics import ALARICDynamics

    calc_module.SKIN_FACTOR = factor
    numba.set_num_threads(1)

    def relaxation(count, seed_):
        rng = np.random.default_rng(seed_)
        radius, angle = np.sqrt(rng.uniform(0, 1, count)), rng.uniform(0, 2 * np.pi, count)
        from ase import Atoms

        atoms = Atoms(numbers=np.zeros(count, int), pbc=False,
                      positions=np.column_stack([radius * np.cos(angle), radius * np.sin(angle), np.zeros(count)]))
        calc = ALARICCalculator(target_density=uniform, target_gradient=no_gradient, dim=2,
                                domain=Circle((0.0, 0.0), 1.0), boundary=boundary, form="log")
        atoms.calc = calc
        return atoms, calc, ALARICDynamics(atoms, eps_dot_min=0.0, eps_min=0.0)

    _, _, warm = relaxation(300, seed + 1)  # loads every compiled loop from numba's cache
    warm.run(3)
    atoms, calc, dyn = relaxation(n, seed)
    load_before = os.getloadavg()
    wall, cpu = clocked(lambda: dyn.run(steps))
    nlist = calc.nlist
    return dict(factor=factor, skin=calc._skin, boundary=boundary, n=n, steps=steps, wall_s=wall, cpu_s=cpu,
                evaluations=int(calc.evaluations), builds=int(getattr(nlist, "builds", -1)),
                pairs_last=int(getattr(nlist, "_pair_count", -1)), epsilon=float(calc.results["epsilon"]),
                h_mean_end=float(np.mean(calc.h_p)), load_before=load_before, load_after=os.getloadavg())


def dynamics_comparison(n, steps, factors, rounds, boundary, seed):
    """The skin factors alternating in fresh one-thread processes; per factor the medians over ``rounds``."""
    env = dict(os.environ, OMP_NUM_THREADS="1", NUMBA_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")

    def child(factor):
        code = (f"import sys, json; sys.path.insert(0, {str(Path(__file__).parent)!r}); "
                f"from bench_alaric import dynamics_child; "
                f"print(json.dumps(dynamics_child({n}, {steps}, {factor}, {boundary!r}, {seed})))")
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, env=env)
        return json.loads(out.stdout.strip().splitlines()[-1])

    for factor in factors:  # untimed: compiles or loads every loop once
        child(factor)
    runs = []
    for k in range(rounds):
        for factor in (factors if k % 2 == 0 else factors[::-1]):
            row = child(factor)
            runs.append(row)
            print(f"round {k} factor {factor}: wall {row['wall_s']:.2f} s, CPU {row['cpu_s']:.2f} s, builds "
                  f"{row['builds']} / {row['evaluations']} evaluations, pairs {row['pairs_last']}, eps "
                  f"{row['epsilon']:.3e}, load {row['load_before'][0]:.1f}", flush=True)
    summary = []
    for factor in factors:
        mine = [r for r in runs if r["factor"] == factor]
        summary.append(dict(factor=factor, **{key: statistics.median(r[key] for r in mine)
                                              for key in ("wall_s", "cpu_s", "builds", "evaluations", "pairs_last",
                                                          "epsilon")}))
    base = summary[0]
    for row in summary:
        row["cpu_over_first"] = row["cpu_s"] / base["cpu_s"]
        row["wall_over_first"] = row["wall_s"] / base["wall_s"]
        # per-round ratios (a load change hits both runs of a round)
        row["cpu_over_first_per_round"] = [
            b["cpu_s"] / a["cpu_s"] for a, b in zip([r for r in runs if r["factor"] == base["factor"]],
                                                    [r for r in runs if r["factor"] == row["factor"]])]
        row["cpu_over_first_median_of_rounds"] = statistics.median(row["cpu_over_first_per_round"])
    return dict(n=n, steps=steps, factors=factors, rounds=rounds, boundary=boundary, seed=seed, runs=runs,
                summary=summary)


def _finish(results, out):
    """Stamp the load average after the run, print it and write the results."""
    results["load_after"] = os.getloadavg()
    print(f"load average {os.getloadavg()}")
    write_json(out, results)


def _sizes(text):
    return [int(float(s)) for s in text.split(",") if s]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="1e5")
    parser.add_argument("--threads", default="1,2")
    parser.add_argument("--dims", default="2,3")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--profile", action="store_true", help="the parts of one evaluation (1 thread)")
    parser.add_argument("--scaling-sizes", default="1e4,1e5,3e5")
    parser.add_argument("--no-scaling", action="store_true")
    parser.add_argument("--memory", action="store_true", help="peak RSS of a 1e6 2D evaluation (a subprocess)")
    parser.add_argument("--no-lammps", action="store_true")
    parser.add_argument("--dynamics", action="store_true",
                        help="only the controlled ALARICDynamics timing against the skin (fresh processes)")
    parser.add_argument("--dyn-n", type=int, default=10000)
    parser.add_argument("--dyn-steps", type=int, default=300)
    parser.add_argument("--dyn-rounds", type=int, default=5)
    parser.add_argument("--dyn-factors", default="0.1,0.2", help="skin factors; ratios are to the first")
    parser.add_argument("--dyn-boundary", default="wall", choices=("wall", "mirror"))
    parser.add_argument("--dyn-seed", type=int, default=0)
    parser.add_argument("--ab-baseline", default=None, metavar="CHECKOUT",
                        help="only: warm one-thread evaluations of this checkout against CHECKOUT (its top folder, "
                             "e.g. from git archive), fresh processes alternating, --ab-rounds rounds per --dims")
    parser.add_argument("--ab-rounds", type=int, default=5)
    parser.add_argument("--out", default=str(Path(__file__).parent / "results" / "bench_alaric.json"))
    args = parser.parse_args()
    dims = [int(d) for d in args.dims.split(",")]
    with_lammps = not args.no_lammps and lammps_available()
    import ase_sphrelax

    # version: this script's checkout; measured: the ase_sphrelax imported (PYTHONPATH may point at a baseline)
    results = dict(version=git_version(), measured=str(Path(ase_sphrelax.__file__).parent), argv=sys.argv[1:],
                   load_before=os.getloadavg(),
                   numba_threads_max=numba.config.NUMBA_NUM_THREADS, rows=[])
    print(f"{results['version']}, measuring {results['measured']}; load average {os.getloadavg()}", flush=True)
    if args.ab_baseline:
        results["ab"] = ab_comparison(args.ab_baseline, dims, _sizes(args.sizes)[0], args.ab_rounds)
        for row in results["ab"]["rows"]:
            print(f"{row['dim']}D N {row['n']}: this {1e3 * row['this_cpu_s']:.1f} ms, baseline "
                  f"{1e3 * row['baseline_cpu_s']:.1f} ms CPU (medians), this / baseline "
                  f"{row['this_over_baseline']:.3f} (median of rounds; range {min(row['per_round']):.3f}-"
                  f"{max(row['per_round']):.3f}); same results bit for bit: {row['same_digests']}")
        return _finish(results, args.out)
    if args.dynamics:
        results["dynamics"] = dynamics_comparison(args.dyn_n, args.dyn_steps,
                                                  [float(f) for f in args.dyn_factors.split(",")], args.dyn_rounds,
                                                  args.dyn_boundary, args.dyn_seed)
        for row in results["dynamics"]["summary"]:
            print(f"skin factor {row['factor']}: median CPU {row['cpu_s']:.2f} s (x{row['cpu_over_first']:.3f}, "
                  f"per-round median x{row['cpu_over_first_median_of_rounds']:.3f}), wall {row['wall_s']:.2f} s, "
                  f"builds {row['builds']} / {row['evaluations']}, eps {row['epsilon']:.3e}")
        return _finish(results, args.out)
    for n in _sizes(args.sizes):
        for dim in dims:
            for nthreads in [int(t) for t in args.threads.split(",")]:
                row = compare(n, dim, nthreads, args.rounds, args.repeats, with_lammps)
                results["rows"].append(row)
                clock = "cpu" if nthreads == 1 else "wall"
                lmp = f", LAMMPS step {row['lammps_' + clock]:.4f} s" if with_lammps else ""
                vs_lmp = f", ALARIC/LAMMPS {row['alaric_over_lammps_' + clock]:.2f}" if with_lammps else ""
                print(f"N {row['n']:8d} {dim}D {nthreads} thr ({clock}): ALARIC {row['alaric_' + clock]:.4f} s "
                      f"({row['neighbours']:.0f} neighbours, {row['h_passes']} H pass(es)), Fan "
                      f"{row['fan_' + clock]:.4f} s{lmp}; ALARIC/Fan {row['alaric_over_fan_' + clock]:.2f}{vs_lmp}; "
                      f"load {row['load_before'][0]:.1f} -> {row['load_after'][0]:.1f}", flush=True)
    numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    if args.profile:
        results["profile"] = []
        for dim in dims:
            prof = profile(_sizes(args.sizes)[0], dim, args.rounds, args.repeats)
            results["profile"].append(prof)
            print(f"profile {dim}D N {prof['n']} (1 thread, CPU ms, load {prof['load'][0]:.1f}):")
            for key, value in prof["parts"].items():
                print(f"    {key:40s} {value if key == 'passes' else 1e3 * value:8.2f}")
    if not args.no_scaling:
        results["scaling"] = []
        for dim in dims:
            sc = scaling(dim, _sizes(args.scaling_sizes), args.rounds, args.repeats)
            results["scaling"].append(sc)
            print(f"scaling {dim}D (1 thread, CPU per particle): " + ", ".join(
                f"N {n}: {1e9 * t:.0f} ns" for n, t in zip(sc["n"], sc["cpu_per_particle"]))
                + f"; relative {[round(x, 2) for x in sc['relative_to_smallest']]}", flush=True)
    numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    if args.memory:
        rss = memory_probe(1_000_000)
        results["peak_rss_mb_1e6_2d"] = rss
        print(f"peak RSS, 1e6 2D particles, two ALARIC evaluations: {rss:.0f} MB")
    results["load_after"] = os.getloadavg()
    results["self_maxrss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    print(f"load average {os.getloadavg()}")
    write_json(args.out, results)


if __name__ == "__main__":
    main()
