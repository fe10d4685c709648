"""Speed against error: Fan's Eq. 2.4 relaxation vs ASE's FIRE, LBFGS and BFGS.

For each scene the same initial particles are relaxed by every method (all built
by :func:`ase_sphrelax.drivers.make_optimizer`, so the first step moves the
fastest particle by ``c h``), and after every step we record

* the number of force evaluations, counted as actual ``FanCalculator.calculate``
  calls (a wrapper on the calculator; ``make_optimizer``'s initial
  ``get_forces`` is included, cached repeats are not),
* the wall time spent inside the optimiser (metric evaluation excluded),
* the error ``E - E_ref`` of Fan's total error (Eq. 3.8), ``E_ref`` the lowest
  energy seen: a long LBFGS run (``--ref-steps`` steps) and all the runs,
* at about 40 log-spaced steps, the kernel-sum quality of
  :mod:`ase_sphrelax.analysis.quality`: mean ``|sum_j V_j W_ij - 1|`` and mean
  ``h |sum_j V_j grad W_ij|`` over particles whose support is inside the domain.

Scenes (h = 2.6 dx, Wendland C2):

* ``circle``: Fan's default circle, centre (0.5, 0.5), radius 0.2, dx = 1/256
  (8224 particles, ``fill`` with jitter 0.1 dx, seed 0, as ``sphrelax relax``);
* ``periodic``: 64 x 64 jittered square lattice (jitter 0.25 dx), periodic;
* ``small``: 12 x 12 periodic, the only scene with BFGS (ASE's BFGS keeps a
  dense 3N x 3N Hessian and diagonalises it every step: O(N^3)).

Goal (issue item 13): an ASE optimiser reaches the error of Eq. 2.4 with
c = 0.01 after 2000 steps with at most a fifth of the force evaluations.

    python benchmarks/bench_speed_vs_error.py            # full (about 30 min on a busy 2-core machine)
    python benchmarks/bench_speed_vs_error.py --quick    # smoke test (< 2 min): smaller scenes, 200 steps

Writes benchmarks/results/speed_vs_error[_quick].json and .png.
"""
from __future__ import annotations

import os

# ASE's BFGS diagonalises a dense Hessian every step; multi-threaded BLAS on a
# busy 2-core machine made that 15x slower (0.08 s -> 1.2 s for 432 x 432).
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import datetime  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import platform  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from ase_sphrelax import FanCalculator  # noqa: E402
from ase_sphrelax.analysis.quality import Quality  # noqa: E402
from ase_sphrelax.build import fill, periodic_box  # noqa: E402
from ase_sphrelax.domains import Circle  # noqa: E402
from ase_sphrelax.drivers import make_optimizer  # noqa: E402
from _provenance import git_version  # noqa: E402

RATIO = 2.6
RESULTS = Path(__file__).resolve().parent / "results"
FAN_REFERENCE_STEPS = 2000  # the issue's yardstick: Eq. 2.4, c = 0.01, 2000 steps
ERROR_FLOOR = 1e-9  # plotted errors are floored at this fraction of the initial error

# (label, optimizer name, c, extra keyword arguments for the optimiser)
METHODS = [
    ("fan c=0.01", "fan", 0.01, {}),
    ("fan c=0.02", "fan", 0.02, {}),
    ("fan c=0.05", "fan", 0.05, {}),
    ("fire", "fire", 0.01, {}),
    ("lbfgs", "lbfgs", 0.01, {}),
]
# parameter experiments for make_optimizer (full mode): same optimisers, other scales
VARIANTS = [
    ("fire c=0.05", "fire", 0.05, {}),
    ("fire c=0.01 dtmax=30dt", "fire", 0.01, {"dtmax_factor": 30.0}),
    ("lbfgs c=0.05", "lbfgs", 0.05, {"uncap_maxstep": True}),
    ("lbfgs c=0.05 memory=20", "lbfgs", 0.05, {"uncap_maxstep": True, "memory": 20}),
]
BFGS = [("bfgs", "bfgs", 0.01, {})]


# -- scenes ---------------------------------------------------------------------------
def scenes(quick):
    """name -> dict(atoms, h, dx, domain, methods, steps)."""
    out = {}
    dx = 1 / 128 if quick else 1 / 256
    circle = Circle((0.5, 0.5), 0.2)
    out["circle"] = dict(atoms=fill(circle, dx, jitter=0.1, seed=0), dx=dx, domain=circle,
                         title=f"circle r=0.2, dx=1/{round(1 / dx)}")
    side = 20 if quick else 64
    out["periodic"] = dict(atoms=periodic_box(side, dx=1.0, jitter=0.25, seed=0), dx=None, domain=None,
                           title=f"periodic {side}x{side}")
    side = 8 if quick else 12
    out["small"] = dict(atoms=periodic_box(side, dx=1.0, jitter=0.25, seed=0), dx=None, domain=None,
                        title=f"periodic {side}x{side} (with BFGS)", bfgs=True)
    for scene in out.values():
        scene["h"] = RATIO * (scene["dx"] or 1.0)
    return out


def calculator(scene):
    return FanCalculator(scene["h"], dx=scene["dx"], domain=scene["domain"], dim=2)


class CountingCalculator:
    """Count ``calc.calculate`` calls (actual evaluations, not cached property reads)."""

    def __init__(self, calc):
        self.calls = 0
        original = calc.calculate

        def counted(*args, **kwargs):
            self.calls += 1
            return original(*args, **kwargs)

        calc.calculate = counted


def optimizer_kwargs(scene, name, c, extra, atoms):
    """Translate the experiment keywords (in units of make_optimizer's own scales) into optimiser kwargs."""
    extra = dict(extra)
    kwargs = {}
    if "dtmax_factor" in extra:
        f = atoms.get_forces()
        dt = math.sqrt(c * scene["h"] / float(np.sqrt((f**2).sum(axis=1)).max()))
        kwargs["dtmax"] = extra.pop("dtmax_factor") * dt
    if "maxstep_h" in extra:
        kwargs["maxstep"] = extra.pop("maxstep_h") * scene["h"]
    if extra.pop("uncap_maxstep", False):
        # ASE's LBFGS raises ValueError for maxstep > 1.0 (absolute length): pass
        # a legal value and restore make_optimizer's 10 c h after construction
        kwargs["_maxstep_after"] = kwargs.get("maxstep", 10.0 * c * scene["h"])
        kwargs["maxstep"] = min(1.0, kwargs["_maxstep_after"])
    kwargs.update(extra)
    return kwargs


def run(scene, method, steps, quality_steps):
    """Relax a copy of the scene's atoms; return the trace dictionary."""
    label, name, c, extra = method
    atoms = scene["atoms"].copy()
    atoms.calc = calculator(scene)
    kwargs = optimizer_kwargs(scene, name, c, extra, atoms)  # may evaluate forces: not counted, not timed
    maxstep_after = kwargs.pop("_maxstep_after", None)
    atoms.calc = calculator(scene)
    counter = CountingCalculator(atoms.calc)
    quality = Quality(scene["h"], dx=scene["dx"], domain=scene["domain"], dim=2)

    trace = dict(label=label, optimizer=name, c=c, kwargs={k: float(v) for k, v in kwargs.items()},
                 step=[], evals=[], wall=[], energy=[], q_step=[], q_evals=[], q_wall=[],
                 kernel_sum_error=[], gradient_error=[])

    def record(k, wall):
        trace["step"].append(k)
        trace["evals"].append(counter.calls)
        trace["wall"].append(wall)
        trace["energy"].append(atoms.get_potential_energy())  # cached: computed with the forces
        if k in quality_steps or k == steps:
            s = quality.compute(atoms).summary()
            trace["q_step"].append(k)
            trace["q_evals"].append(counter.calls)
            trace["q_wall"].append(wall)
            trace["kernel_sum_error"].append(s["kernel_sum_error_mean"])
            trace["gradient_error"].append(s["gradient_error_mean"])

    t0 = time.perf_counter()
    opt = make_optimizer(name, atoms, c=c, **kwargs)
    if maxstep_after is not None:
        opt.maxstep = maxstep_after
        trace["kwargs"]["maxstep"] = maxstep_after
    gen = opt.irun(fmax=0.0, steps=steps)
    next(gen)  # initial forces
    wall = time.perf_counter() - t0
    record(0, wall)
    for k in range(1, steps + 1):
        t = time.perf_counter()
        try:
            next(gen)
        except StopIteration:
            break
        wall += time.perf_counter() - t
        record(k, wall)
    f = atoms.get_forces()
    trace["final_fmax"] = float(np.sqrt((f**2).sum(axis=1)).max())
    trace["final_energy"] = trace["energy"][-1]
    trace["extra_calls_per_step"] = (trace["evals"][-1] - 1) / max(1, trace["step"][-1])
    return trace


def reference_energy(scene, steps):
    """Final energy and max |F| (relative to the initial one) of a long LBFGS run."""
    atoms = scene["atoms"].copy()
    atoms.calc = calculator(scene)
    f0 = float(np.sqrt((atoms.get_forces() ** 2).sum(axis=1)).max())
    opt = make_optimizer("lbfgs", atoms, c=0.01)
    opt.run(fmax=1e-8 * f0, steps=steps)
    f = float(np.sqrt((atoms.get_forces() ** 2).sum(axis=1)).max())
    return atoms.get_potential_energy(), f / f0, opt.nsteps


def first_reaching(trace, key, target):
    """(evals, wall, step) at the first record with ``E - E_ref <= target``, or None."""
    err = np.asarray(trace["error"])
    hit = np.nonzero(err <= target)[0]
    if len(hit) == 0:
        return None
    k = int(hit[0])
    return dict(evals=trace["evals"][k], wall=trace["wall"][k], step=trace["step"][k])


def analyse(result):
    traces = result["traces"]
    e_ref = min([result["ref_energy"]] + [min(t["energy"]) for t in traces])
    result["e_ref"] = e_ref
    for t in traces:
        t["error"] = [e - e_ref for e in t["energy"]]
    fan = next(t for t in traces if t["label"] == "fan c=0.01")
    k = min(FAN_REFERENCE_STEPS, fan["step"][-1])
    idx = fan["step"].index(k)
    target = fan["error"][idx]
    result["target"] = dict(fan_steps=k, fan_evals=fan["evals"][idx], fan_wall=fan["wall"][idx], error=target,
                            fan_min_error=min(fan["error"][: idx + 1]))
    result["to_target"] = {}
    for t in traces:
        hit = first_reaching(t, "error", target)
        if hit is not None:
            hit["evals_fraction"] = hit["evals"] / fan["evals"][idx]
            hit["wall_fraction"] = hit["wall"] / fan["wall"][idx]
        result["to_target"][t["label"]] = hit


def plot(results, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(results)
    fig, axes = plt.subplots(len(names), 3, figsize=(16, 4.4 * len(names)), squeeze=False)
    for row, name in zip(axes, names):
        res = results[name]
        for t in res["traces"]:
            style = "-" if t["optimizer"] == "fan" else "--"
            # E - E_ref reaches 0 (to rounding) for runs that found E_ref: floor the log axis
            err = np.maximum(np.asarray(t["error"]), ERROR_FLOOR * t["error"][0])
            line, = row[0].plot(t["evals"], err, style, lw=1.2, label=t["label"])
            row[1].plot(t["wall"], err, style, lw=1.2, color=line.get_color())
            row[2].plot(t["q_evals"], t["kernel_sum_error"], style + "o", ms=2.5, lw=1.0, color=line.get_color())
        target = res["target"]
        for ax in row[:2]:
            ax.axhline(target["error"], color="k", lw=0.7, ls=":")
        row[0].axvline(target["fan_evals"] / 5, color="k", lw=0.7, ls=":")
        row[0].set_xscale("log")
        row[0].set_xlabel("force evaluations")
        row[1].set_xscale("log")
        row[1].set_xlabel("wall time [s]")
        row[2].set_xscale("log")
        row[2].set_xlabel("force evaluations")
        for ax in row[:2]:
            ax.set_yscale("log")
            ax.set_ylabel("E - E_ref")
        row[2].set_yscale("log")
        row[2].set_ylabel("mean |sum_j V_j W_ij - 1| (interior)")
        row[0].set_title(f"{res['title']}, N={res['n']}: error vs evaluations\n"
                         f"(dotted: Eq. 2.4 c=0.01 at {target['fan_steps']} steps, and 1/5 of its evaluations)",
                         fontsize=9)
        row[1].set_title("error vs wall time", fontsize=9)
        row[2].set_title("kernel-sum error vs evaluations", fontsize=9)
        row[0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=75)
    plt.close(fig)


def slim(result, points=150):
    """Copy for JSON: traces thinned to about ``points`` log-spaced records, 4 significant digits."""
    def r4(values):
        return [float(f"{v:.4g}") for v in values]

    out = {k: v for k, v in result.items() if k != "traces"}
    out["traces"] = []
    for t in result["traces"]:
        n = len(t["evals"])
        keep = sorted(set(np.unique(np.geomspace(1, n, points).astype(int) - 1).tolist()) | {0, n - 1})
        s = {k: v for k, v in t.items() if not isinstance(v, list)}
        for k in ("step", "evals", "q_step", "q_evals"):
            if k in t:
                s[k] = [t[k][i] for i in keep] if k in ("step", "evals") else t[k]
        for k in ("wall", "error"):
            s[k] = r4(t[k][i] for i in keep)
        for k in ("q_wall", "kernel_sum_error", "gradient_error"):
            s[k] = r4(t[k])
        out["traces"].append(s)
    return out


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="smoke test: smaller scenes, 200 steps")
    parser.add_argument("--steps", type=int, default=None, help="steps per method (default 2000; quick 200)")
    parser.add_argument("--ref-steps", type=int, default=None, help="LBFGS steps for E_ref (default 6000; quick 500)")
    parser.add_argument("--scenes", nargs="*", default=None, choices=["circle", "periodic", "small"])
    parser.add_argument("--no-variants", action="store_true", help="skip the make_optimizer parameter experiments")
    parser.add_argument("--out", default=None, help="output stem (default benchmarks/results/speed_vs_error[_quick])")
    parser.add_argument("--replot", metavar="JSON", default=None,
                        help="only redraw the PNG (beside the JSON) from a results JSON of this script")
    args = parser.parse_args(argv)
    if args.replot:
        data = json.loads(Path(args.replot).read_text())
        data["scenes"] = {k: slim(v) for k, v in data["scenes"].items()}
        Path(args.replot).write_text(json.dumps(data))
        plot(data["scenes"], Path(args.replot).with_suffix(".png"))
        print(f"wrote {Path(args.replot).with_suffix('.png')}")
        return
    steps = args.steps or (200 if args.quick else FAN_REFERENCE_STEPS)
    ref_steps = args.ref_steps or (500 if args.quick else 6000)
    stem = Path(args.out) if args.out else RESULTS / ("speed_vs_error_quick" if args.quick else "speed_vs_error")
    variants = not (args.quick or args.no_variants)
    quality_steps = set(np.unique(np.geomspace(1, steps, 40).astype(int)).tolist()) | {0}

    all_scenes = scenes(args.quick)
    chosen = args.scenes or list(all_scenes)
    started = datetime.datetime.now(datetime.timezone.utc)
    load_before = os.getloadavg()
    stem.parent.mkdir(parents=True, exist_ok=True)
    partial = stem.parent / (stem.name + "_partial.json")  # per-scene results while running
    results = {}
    failed = {}
    t_start = time.perf_counter()
    for name in chosen:
        scene = all_scenes[name]
        methods = METHODS + (VARIANTS if variants else []) + (BFGS if scene.get("bfgs") else [])
        e_ref, f_rel, ref_n = reference_energy(scene, ref_steps)
        print(f"[{time.perf_counter() - t_start:6.0f} s] {name}: N = {len(scene['atoms'])}, "
              f"LBFGS reference {ref_n} steps, E = {e_ref:.10g}, max|F|/max|F0| = {f_rel:.2e}", flush=True)
        traces = []
        for method in methods:
            try:
                traces.append(run(scene, method, steps, quality_steps))
            except ValueError as err:  # e.g. ASE (L)BFGS refuses maxstep > 1.0 (absolute length units)
                failed[f"{name}: {method[0]}"] = str(err)
                print(f"[{time.perf_counter() - t_start:6.0f} s]   {method[0]:28s} FAILED: {err}", flush=True)
                continue
            t = traces[-1]
            print(f"[{time.perf_counter() - t_start:6.0f} s]   {t['label']:28s} E = {t['final_energy']:.10g} "
                  f"evals {t['evals'][-1]} wall {t['wall'][-1]:.1f} s", flush=True)
        res = dict(title=scene["title"], n=len(scene["atoms"]), h=scene["h"], dx=scene["dx"], steps=steps,
                   ref_energy=e_ref, ref_fmax_rel=f_rel, ref_steps=ref_n, traces=traces)
        analyse(res)
        results[name] = res
        partial.write_text(json.dumps({k: slim(v) for k, v in results.items()}))

    load_after = os.getloadavg()
    print()
    for name, res in results.items():
        tg = res["target"]
        print(f"{name} ({res['title']}, N = {res['n']}): E_ref = {res['e_ref']:.10g}; target error "
              f"(Eq. 2.4 c=0.01 after {tg['fan_steps']} steps, {tg['fan_evals']} evaluations, "
              f"{tg['fan_wall']:.1f} s) = {tg['error']:.3e}")
        print(f"  {'method':28s} {'final E-E_ref':>13s} {'KS err':>9s} {'grad err':>9s} | "
              f"{'evals to target':>15s} {'fraction':>8s} {'wall':>7s} {'fraction':>8s}")
        for t in res["traces"]:
            hit = res["to_target"][t["label"]]
            reach = (f"{hit['evals']:15d} {hit['evals_fraction']:8.3f} {hit['wall']:7.2f} {hit['wall_fraction']:8.3f}"
                     if hit else f"{'not reached':>15s}")
            print(f"  {t['label']:28s} {t['error'][-1]:13.3e} {t['kernel_sum_error'][-1]:9.2e} "
                  f"{t['gradient_error'][-1]:9.2e} | {reach}")
        ase_hits = [(h["evals_fraction"], lab) for lab, h in res["to_target"].items()
                    if h and not lab.startswith("fan")]
        if ase_hits:
            best = min(ase_hits)
            verdict = "met" if best[0] <= 0.2 else "MISSED"
            print(f"  goal (ASE optimiser <= 1/5 of the evaluations): {verdict}, best {best[1]} at {best[0]:.3f}")
            res["goal_met"] = bool(best[0] <= 0.2)
            res["goal_best"] = dict(label=best[1], evals_fraction=best[0])
        else:
            print("  goal: MISSED, no ASE optimiser reached the target error")
            res["goal_met"] = False
    for key, err in failed.items():
        print(f"FAILED {key}: {err}")
    print(f"load average before {load_before[0]:.2f}, after {load_after[0]:.2f} (1 min); "
          f"total {time.perf_counter() - t_start:.0f} s")

    stem.parent.mkdir(parents=True, exist_ok=True)
    plot(results, stem.with_suffix(".png"))
    out = dict(date_utc=started.isoformat(timespec="seconds"),
               git=git_version(),
               machine=dict(platform=platform.platform(), cpus=os.cpu_count(), python=platform.python_version()),
               load_average_before=load_before, load_average_after=load_after, quick=args.quick, failed=failed,
               scenes={k: slim(v) for k, v in results.items()})
    stem.with_suffix(".json").write_text(json.dumps(out))
    partial.unlink(missing_ok=True)
    print(f"wrote {stem.with_suffix('.json')} and {stem.with_suffix('.png')}")


if __name__ == "__main__":
    main()
