"""Fan's relaxation at 1e6 particles end to end, against LAMMPS's FIRE on the same start (issue 33, item 2).

Scenes: Fan's circle (centre (0.5, 0.5), radius 0.2; in 2D the issue's ``dx = 0.000354 sqrt(1e6 / n)``,
1 002 739 particles at ``n = 1e6``) and the sphere of the same radius (``dx = (V / n)^(1/3)``), filled by
``ase_sphrelax.build.fill(domain, dx, jitter=0.1, seed=0)``, ``h = 2.6 dx``.

The measure, declared before any run: the interior mean ``h |sum_j V_j grad W_ij|`` of
:func:`ase_sphrelax.analysis.quality.quality_summary` (``gradient_error_mean``, particles at least ``h``
inside the wall), target ``--target`` (6e-4, what 300 of ASE's FIRE steps reached on the 2D circle).

* **ours** (timed, ``--threads`` numba threads): fill, ``FanCalculator(h=, dx=, domain=)``,
  ``make_optimizer("fire", atoms)`` (the package's defaults; since ``FIRE_DYNAMICS``, ``dtmax`` 2.5 dt and a
  constant mixing ``a = 0.15``, about half the steps of ASE's FIRE dynamics on this start,
  ``benchmarks/bench_optimizer_steps.py``: the stored 2D and 3D runs, 310 and 285 steps, were taken with ASE's
  ``dtmax`` 10 dt and ``a`` 0.1 shrinking by 0.99 a step), steps until the measure is at most the
  target, checked every ``--check-every`` steps from the forces the step already has (an interior
  particle's force is the pair force ``-2 v0^2 sum_j grad W_ij``, so the measure is
  ``h |F_i| / (2 v0)``; the time of the check is included); the end state is then scored by
  ``quality_summary`` itself (not timed). numba's compilation is done on a small system first and
  not counted (its on-disk cache makes it a once-per-machine cost). ``--repeat`` runs (default 3): the
  record is the run of median time, every run's time in ``wall_times``.
* **LAMMPS** (``lammps_io.run``, ``min_style fire``, ``style="table"``, ``--threads`` OpenMP threads; the
  wall term by ``fix external``): first an untimed trajectory run of ``--lammps-steps`` steps that dumps
  every ``--dump-every`` steps (:func:`lammps_io.trajectory_files`), each frame scored by
  ``quality_summary``; ``S*`` is the first dumped step at or below the target. Then the timed run:
  ``lammps_io.run(..., steps=S*)`` end to end (deck, data file, minimisation, dump read back), whose
  final state is scored again. The ratio is ours / LAMMPS (goal <= 0.5) and ours alone (goal <= 30 s
  on 2 threads, 2D and 3D).

Phases (each merges its part into ``--out``; the load average is printed and stored with each):

    python benchmarks/bench_fan_1e6.py --phase trajectory          # LAMMPS's S* (untimed; any load)
    python benchmarks/bench_fan_1e6.py --phase timed               # ours and LAMMPS's S* steps, timed
    python benchmarks/bench_fan_1e6.py --figure                    # docs/_static/bench_fan_1e6.png

In 3D LAMMPS's trajectory at 1e6 costs over an hour here; its step count comes from a trajectory at 1e5
and its time per step from a short timed run at 1e6 (``--lammps-estimate-from``), an estimate:

    python benchmarks/bench_fan_1e6.py --phase trajectory --dims 3 --n 1e5 --lammps-steps 1200 --dump-every 50 \
        --out benchmarks/results/bench_fan_1e6_3d_steps_1e5.json
    python benchmarks/bench_fan_1e6.py --phase timed --dims 3 \
        --lammps-estimate-from benchmarks/results/bench_fan_1e6_3d_steps_1e5.json

``--dims 2,3`` and ``--n 1e6`` choose the scenes. Each timing is stored with the machine it was taken on
(``machine``: the CPU, numba's compile target, the vector width, the caches): the same code took 28 s on the sphere
on one machine of this project's kind and 39-55 s on another. ``--reuse-lammps`` keeps LAMMPS's step counts, and
its times only when they were taken on the same kind of machine (else LAMMPS is timed again). Writes
``benchmarks/results/bench_fan_1e6.json``.
"""
from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

import numpy as np

try:
    from _provenance import git_version, machine, same_machine, write_json
except ImportError:
    from benchmarks._provenance import git_version, machine, same_machine, write_json

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "benchmarks" / "results" / "bench_fan_1e6.json"
FIGURE = ROOT / "docs" / "_static" / "bench_fan_1e6.png"
RATIO = 2.6  # h / dx
RADIUS = 0.2


def scene_dx(dim, n):
    """The spacing of the scene with about ``n`` particles."""
    return 0.000354 * np.sqrt(1e6 / n) if dim == 2 else (4.0 / 3.0 * np.pi * RADIUS**3 / n) ** (1.0 / 3.0)


def scene(dim, n):
    """``(domain, dx, atoms)``: Fan's circle or sphere filled with about ``n`` particles."""
    from ase_sphrelax.build import fill
    from ase_sphrelax.domains import Circle, Sphere

    domain = Circle((0.5, 0.5), RADIUS) if dim == 2 else Sphere((0.5, 0.5, 0.5), RADIUS)
    dx = scene_dx(dim, n)
    return domain, dx, fill(domain, dx, jitter=0.1, seed=0)


def score(atoms, domain, dx):
    """The declared measure: ``quality_summary``'s interior ``gradient_error_mean``."""
    from ase_sphrelax.analysis.quality import quality_summary

    return float(quality_summary(atoms, RATIO * dx, dx, domain)["gradient_error_mean"])


def warm_up(dim):
    """Compile (or load from numba's cache) everything the timed run calls, on a small system."""
    from ase_sphrelax import FanCalculator, make_optimizer

    domain, dx, atoms = scene(dim, 2000)
    atoms.calc = FanCalculator(h=RATIO * dx, dx=dx, domain=domain)
    make_optimizer("fire", atoms).run(steps=3, fmax=0)
    score(atoms, domain, dx)
    interior_mean_norm(atoms.calc.results["forces"], domain.phi(atoms.positions), -RATIO * dx)  # the run's check


def _norm_sum_chunk(f_pc, phi_p, below, out, first, last):
    for p in range(first, last):
        if phi_p[p] <= below:
            out[0] += np.sqrt(f_pc[p, 0] * f_pc[p, 0] + f_pc[p, 1] * f_pc[p, 1] + f_pc[p, 2] * f_pc[p, 2])
            out[1] += 1.0


def interior_mean_norm(f_pc, phi_p, below):
    """Mean of ``|f_p|`` over the points with ``phi_p <= below``, in one pass on the package's threads (numpy's
    norms, mask and mean of 1e6 points took 15 ms on one thread, the check 31 times in a 2D run)."""
    import numba

    from ase_sphrelax.parallel import reduce_chunks

    global _NORM_SUM
    if _NORM_SUM is None:
        _NORM_SUM = numba.njit(nogil=True, cache=True)(_norm_sum_chunk)
    outs = reduce_chunks(_NORM_SUM, len(f_pc), (f_pc, np.asarray(phi_p, dtype=float), float(below)), 2)
    return float(sum(o[0] for o in outs) / sum(o[1] for o in outs))


_NORM_SUM = None


def run_ours(dim, n, target, check_every, max_steps, **optimizer_kwargs):
    """Ours end to end until the measure reaches ``target``: a dict of times, steps and the trace
    (``optimizer_kwargs``: passed to ``make_optimizer``, for scans; the bench passes none)."""
    from ase_sphrelax import FanCalculator, make_optimizer

    t0 = time.perf_counter()
    domain, dx, atoms = scene(dim, n)
    t_fill = time.perf_counter() - t0
    h = RATIO * dx
    atoms.calc = FanCalculator(h=h, dx=dx, domain=domain)
    opt = make_optimizer("fire", atoms, **optimizer_kwargs)
    v0 = dx**dim
    trace = []
    reached = False
    for _ in opt.irun(fmax=0.0, steps=max_steps):
        if opt.nsteps % check_every:
            continue
        f_pc = atoms.calc.results["forces"]  # the step's own forces (no copy)
        measure = h / (2.0 * v0) * interior_mean_norm(f_pc, domain.phi(atoms.positions), -h)
        trace.append([int(opt.nsteps), time.perf_counter() - t0, measure])
        if measure <= target:
            reached = True
            break
    wall = time.perf_counter() - t0
    final = score(atoms, domain, dx)
    return dict(n=len(atoms), dx=dx, machine=machine(), wall_time=wall, fill_time=t_fill, steps=int(opt.nsteps),
                reached=reached,
                final_measure=final, final_below_target=bool(final <= target), trace=trace,
                list_builds=int(atoms.calc.nlist.builds))


def repeated(run, times):
    """``run()`` ``times`` times (at least once): the record of the run of median wall time (the lower median for an
    even count), with every run's time in ``wall_times`` (in the order run)."""
    if times < 1:
        raise ValueError(f"repeat must be at least 1, got {times}")
    records = [run() for _ in range(times)]
    chosen = sorted(records, key=lambda r: r["wall_time"])[(times - 1) // 2]
    return dict(chosen, wall_times=[r["wall_time"] for r in records])


def lammps_trajectory(dim, n, target, steps, dump_every, threads):
    """Untimed LAMMPS FIRE run dumping every ``dump_every`` steps; each frame scored."""
    import lammps_io

    domain, dx, atoms = scene(dim, n)
    frames = []
    with tempfile.TemporaryDirectory(prefix="bench_fan_1e6_") as work:
        t0 = time.perf_counter()
        lammps_io.run(atoms, RATIO * dx, dx, domain=domain, steps=steps, style="table", nthreads=threads,
                      workdir=work, dump_every=dump_every)
        wall = time.perf_counter() - t0
        for step, path in lammps_io.trajectory_files(work):
            frame = lammps_io.read_dump(path, dim=dim, reference=atoms)
            frames.append([step, score(frame, domain, dx)])
            path.unlink()
            print(f"  {dim}D LAMMPS step {step}: {frames[-1][1]:.3e}", flush=True)
    below = [s for s, m in frames if m <= target]
    return dict(n=len(atoms), dx=dx, steps=steps, dump_every=dump_every, trace=frames,
                first_step_at_target=below[0] if below else None, wall_time_with_dumps=wall)


def run_lammps(dim, n, steps, threads):
    """Timed LAMMPS FIRE run of ``steps`` steps end to end, its final state scored."""
    import lammps_io

    domain, dx, atoms = scene(dim, n)
    t0 = time.perf_counter()
    relaxed = lammps_io.run(atoms, RATIO * dx, dx, domain=domain, steps=steps, style="table", nthreads=threads)
    wall = time.perf_counter() - t0
    return dict(steps=steps, machine=machine(), wall_time=wall, iterations=int(relaxed.info["lammps"]["iterations"]),
                final_measure=score(relaxed, domain, dx))


def stored_lammps(rec, here):
    """Which LAMMPS time stored in a scene's record ``rec`` a timed run on the machine ``here``
    (:func:`_provenance.machine`) may divide by: ``"estimate"`` (3D: the rate run's), ``"run"`` (the timed run of
    S* steps) or None, when the one stored was taken on another machine or on one not recorded (a ratio across
    machines would compare the machines). LAMMPS's step counts hold on any machine; only its times are checked."""
    estimate, run = rec.get("lammps_estimate") or {}, rec.get("lammps") or {}
    if estimate.get("wall_time") and same_machine(estimate.get("rate_run", {}).get("machine"), here):
        return "estimate"
    if run.get("wall_time") and same_machine(run.get("machine"), here):
        return "run"
    return None


def load(path):
    return json.loads(Path(path).read_text()) if Path(path).exists() else {}


def figure(result, path=FIGURE):
    """Measure against step (ours and LAMMPS) per dimension, with the target and the wall times."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ase_sphrelax.plotting import save_figure

    dims = sorted(result.get("scenes", {}))
    fig, axes = plt.subplots(1, len(dims), figsize=(5.2 * len(dims), 3.8), squeeze=False)
    for ax, key in zip(axes[0], dims):
        rec = result["scenes"][key]
        target = result["target"]
        ours, traj = rec.get("ours"), rec.get("lammps_trajectory")
        if ours:
            s, _, m = np.array(ours["trace"]).T
            ax.semilogy(s, m, label=f"ours (FIRE), {ours['wall_time']:.0f} s to the target")
        estimate = rec.get("lammps_estimate")
        if traj is None and estimate is not None:  # 3D: LAMMPS's trajectory at the smaller N
            traj = load(ROOT / estimate["steps_from"])["scenes"][key]["lammps_trajectory"]
        if traj:
            s, m = np.array(traj["trace"]).T
            timed = rec.get("lammps")
            if timed:
                extra = f", {timed['wall_time']:.0f} s to step {timed['steps']}"
            elif estimate and estimate["wall_time"]:
                extra = f" at N = {traj['n']:,}; at 1e6 about {estimate['wall_time']:.0f} s"
            else:
                extra = ""
            ax.semilogy(s, m, "o-", ms=3, label=f"LAMMPS FIRE{extra}")
        ax.axhline(target, color="k", lw=0.8, ls="--", label=f"target {target:g}")
        ax.set_xlabel("optimiser step")
        ax.set_ylabel(r"interior mean $h\,|\sum_j V_j \nabla W_{ij}|$")
        ax.set_title(f"{key}: N = {(ours or traj or {}).get('n', 0):,}")
        ax.legend(fontsize=8)
    machines = {f"{m['cpu']} ({m['compile_target']}, {m['vector']})" for m in
                (result["scenes"][key].get("ours", {}).get("machine") for key in dims) if m}
    if machines:  # the times hold on this machine only
        fig.suptitle(f"timed on {', '.join(sorted(machines))}, {result.get('threads', 2)} threads", fontsize=9)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    save_figure(fig, path, dpi=90, colors=64)
    print(f"wrote {path}")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--phase", choices=("trajectory", "timed"), default=None)
    parser.add_argument("--dims", default="2,3", help="comma separated dimensions (default 2,3)")
    parser.add_argument("--n", type=float, default=1e6, help="particles, about (default 1e6)")
    parser.add_argument("--threads", type=int, default=2, help="numba / OpenMP threads (default 2)")
    parser.add_argument("--target", type=float, default=6e-4, help="interior mean h|sum V grad W| (default 6e-4)")
    parser.add_argument("--repeat", type=int, default=3,
                        help="timed phase: runs of ours; the one of median time is stored, all times in wall_times "
                             "(default 3: the machine's speed moves a single run by a fifth or more)")
    parser.add_argument("--check-every", type=int, default=5, help="our measure every this many steps (default 5)")
    parser.add_argument("--max-steps", type=int, default=2000, help="our step cap (default 2000)")
    parser.add_argument("--lammps-steps", type=int, default=1000, help="the trajectory run's steps (default 1000)")
    parser.add_argument("--dump-every", type=int, default=50, help="the trajectory run's dump interval (default 50)")
    parser.add_argument("--lammps-estimate-from", type=Path, default=None,
                        help="timed phase: LAMMPS's steps to the target from this file's trajectory (a smaller N), "
                             "its time per step from a timed run of --lammps-rate-steps here (an estimate)")
    parser.add_argument("--lammps-rate-steps", type=int, default=50, help="the estimate's timed steps (default 50)")
    parser.add_argument("--reuse-lammps", action="store_true",
                        help="timed phase: keep LAMMPS's step count stored in --out, and its time when it was "
                             "taken on this machine (else LAMMPS is timed again here)")
    parser.add_argument("--out", type=Path, default=OUT)
    parser.add_argument("--figure", action="store_true", help="draw the figure from --out and stop")
    args = parser.parse_args(argv)
    result = load(args.out)
    if args.figure:
        figure(result)
        return
    if args.phase is None:
        parser.error("give --phase trajectory or --phase timed (or --figure)")
    import numba

    numba.set_num_threads(args.threads)
    result.update(target=args.target, threads=args.threads, ratio_h_over_dx=RATIO)
    result.setdefault("scenes", {})
    result.setdefault("runs", [])
    for dim in [int(d) for d in args.dims.split(",")]:
        key = f"{dim}D"
        rec = result["scenes"].setdefault(key, {})
        load_start, started = os.getloadavg(), time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
        print(f"{key}: phase {args.phase}, load average {load_start[0]:.2f}", flush=True)
        if args.phase == "trajectory":
            rec["lammps_trajectory"] = lammps_trajectory(dim, args.n, args.target, args.lammps_steps,
                                                         args.dump_every, args.threads)
            print(f"{key}: LAMMPS reaches {args.target:g} at step {rec['lammps_trajectory']['first_step_at_target']}")
        else:
            warm_up(dim)
            ours = repeated(lambda: run_ours(dim, args.n, args.target, args.check_every, args.max_steps),
                            args.repeat)
            rec["ours"] = ours
            print(f"{key}: ours {ours['wall_time']:.1f} s (the median of {ours['wall_times']}), {ours['steps']} steps, "
                  f"final {ours['final_measure']:.3e}", flush=True)
            traj = rec.get("lammps_trajectory")
            rec["goals"] = {"ours <= 30 s": bool(ours["reached"] and ours["wall_time"] <= 30.0)}
            kept = stored_lammps(rec, ours["machine"]) if args.reuse_lammps else None
            stored_estimate = rec.get("lammps_estimate") or {}
            steps_from = args.lammps_estimate_from
            if steps_from is None and args.reuse_lammps and kept is None and stored_estimate.get("steps_from"):
                # LAMMPS's step count does not depend on the machine, its time per step does: timed again here
                steps_from = Path(stored_estimate["steps_from"])
                print(f"{key}: the stored LAMMPS rate was timed on another machine (or one not recorded): "
                      f"timing it here", flush=True)
            if steps_from is not None:
                # LAMMPS's steps to the target from a smaller system's trajectory, its time per step
                # measured here over --lammps-rate-steps: an estimate, stored as such
                steps_path = steps_from if steps_from.is_absolute() else ROOT / steps_from
                small = load(steps_path)["scenes"][key]["lammps_trajectory"]
                rate = run_lammps(dim, args.n, args.lammps_rate_steps, args.threads)
                rate["per_step"] = rate["wall_time"] / args.lammps_rate_steps
                star = small["first_step_at_target"]
                estimate = dict(rate_run=rate, steps_from=str(steps_from), steps_from_n=small["n"],
                                first_step_at_target=star,
                                wall_time=None if star is None else rate["per_step"] * star)
                rec["lammps_estimate"] = estimate
                if star is not None:
                    rec["ratio_ours_over_lammps_estimate"] = ours["wall_time"] / estimate["wall_time"]
                    print(f"{key}: LAMMPS {rate['per_step']:.2f} s per step at N = {ours['n']}, {star} steps at "
                          f"N = {small['n']}: about {estimate['wall_time']:.0f} s; ours / LAMMPS about "
                          f"{rec['ratio_ours_over_lammps_estimate']:.2f}")
            elif kept == "estimate":
                # our code changed, LAMMPS did not, the machine is the same: keep its stored estimate
                rec["ratio_ours_over_lammps_estimate"] = ours["wall_time"] / stored_estimate["wall_time"]
                print(f"{key}: LAMMPS's stored estimate {stored_estimate['wall_time']:.0f} s; ours / LAMMPS "
                      f"about {rec['ratio_ours_over_lammps_estimate']:.2f}")
            elif kept == "run":
                # our code changed, LAMMPS did not, the machine is the same: keep its timed run
                stored_run = rec["lammps"]
                ratio = ours["wall_time"] / stored_run["wall_time"]
                rec["ratio_ours_over_lammps" if stored_run["reached"] else "ratio_ours_over_lammps_at_most"] = ratio
                rec["goals"]["ours / LAMMPS <= 0.5"] = bool(ours["reached"] and ratio <= 0.5)
                print(f"{key}: LAMMPS's stored run {stored_run['wall_time']:.1f} s; ours / LAMMPS {ratio:.2f}")
            elif traj is not None:
                # LAMMPS at the target: the timed run stops at S*; never there: its whole trajectory's
                # length, and the ratio is an upper bound (LAMMPS would need longer). With --reuse-lammps
                # this is the stored run timed again here: it was timed on another machine (or one not recorded)
                star = traj["first_step_at_target"]
                rec["lammps"] = run_lammps(dim, args.n, traj["steps"] if star is None else star, args.threads)
                rec["lammps"]["reached"] = star is not None
                ratio = ours["wall_time"] / rec["lammps"]["wall_time"]
                rec.pop("ratio_ours_over_lammps_at_most" if star is not None else "ratio_ours_over_lammps", None)
                rec["ratio_ours_over_lammps" if star is not None else "ratio_ours_over_lammps_at_most"] = ratio
                print(f"{key}: LAMMPS {rec['lammps']['wall_time']:.1f} s for {rec['lammps']['steps']} steps, final "
                      f"{rec['lammps']['final_measure']:.3e}; ours / LAMMPS {'' if star else '< '}{ratio:.2f}")
                rec["goals"]["ours / LAMMPS <= 0.5"] = bool(ours["reached"] and ratio <= 0.5)
            else:
                # no LAMMPS number of this machine to divide by: no ratio (an older one would compare machines)
                for stale in ("ratio_ours_over_lammps", "ratio_ours_over_lammps_at_most",
                              "ratio_ours_over_lammps_estimate"):
                    rec.pop(stale, None)
        load_end = os.getloadavg()
        print(f"{key}: load average {load_end[0]:.2f} at the end", flush=True)
        result["runs"].append(dict(phase=args.phase, scene=key, version=git_version(),
                                   started=started, machine=machine(),
                                   load_average_start=load_start, load_average_end=load_end,
                                   command="python benchmarks/bench_fan_1e6.py " + " ".join(argv or [])))
        write_json(args.out, result)


if __name__ == "__main__":
    import sys

    main(sys.argv[1:])
