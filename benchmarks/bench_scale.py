"""Every method from 1e4 to 1e6 particles: time per step, its exponent in N, peak memory per particle (issue 33, item 4).

Methods (``--methods``, comma separated):

* ``fan2d``, ``fan3d``: FanCalculator + ``make_optimizer("fan")`` (Eq. 2.4) on ``build.fill`` of a circle
  (centre (0.5, 0.5), radius 0.2; the issue's 1e6 case at dx = 0.000354) / a sphere (centre (0.5,)*3, radius 0.2),
  jitter 0.1 dx, h = 2.6 dx, the domain's level-set wall;
* ``bipi2d``: BIPI (``BIPICalculator.from_paper(2, dx, ...)``, ``BIPIPacker``) in the Stanford 2D bunny
  (``ase_sphrelax/data/bunny.edges``, 882 segments), Step-1 fill (``initial_fill``), Step 2c iterations (all
  particles evaluated) after Step 2b;
* ``bipi3d``: the same in a torus triangle mesh (``trimesh.creation.torus``, major radius 0.3, minor 0.12,
  48 x 24 sections, 2304 triangles; ``BoundaryTriangles.from_trimesh``); in 3D BIPI's and ALARIC's default keeps no
  Verlet list (``store_list=None``: the list alone would be 630 / 440 B of the 900 B goal per particle);
* ``alaric2d``, ``alaric3d``: ``ALARICCalculator`` + ``ALARICDynamics`` (S+F+V, uniform target rho* = 1) in the disc /
  ball holding N particles at unit spacing (``build.fill``, dx = 1), mirror boundary (``resolve_boundary("auto")``);
* ``parvi2d``: ``ParVISampler`` on the 2D standard normal (``get_target("gaussian")``), ``check=False``.

Per size (``--sizes``; ``--quick``: 1e3, 3e3, 1e4) and method, one fresh child process on one numba thread:
it first runs the method on a small system (numba's cache loaded, every loop compiled), then builds the N-particle
start, resets the peak-RSS counter (``/proc/self/clear_refs``) and reads the resident set (the baseline: the
particles are in it), sets the method up (calculator, lists, driver) and runs ``--steps`` steps. Time per step is the
median wall (and CPU) time of the steps after the first (the first builds the lists); ParVISampler has no public
step, so its time per step is (t(2 + k steps) - t(2 steps)) / k of two runs. Memory: the peak RSS (VmHWM) minus the
baseline, per particle (what the method needs beyond the particle positions; numba's allocations are counted, which
tracemalloc misses). The exponent is the least-squares slope of log(time per step) on log(N) over the sizes
measured. 1e6 runs only for a method whose 1e5 step, times 10, is under ``--max-step-1e6`` seconds.

"Time to a stated quality" (``--quality-runs``, only where cheap: ``QUALITY_RUNS``): each method's own
stopping rule, capped (``--quality-cap`` seconds of wall time), in a child process:

* Fan: Eq. 2.4 until the interior mean h |sum V grad W| (``quality_summary``) is <= 6e-4 (the issue's figure);
* BIPI: the packer's own rule (``BIPIPacker.run``, tol 0.01 over its window);
* ALARIC: ``relax_density`` (its epsilon-dot stop), once directly at N and once from N / 4 with one split
  (the coarse-to-fine route);
* SPH-ParVI: ``ParVISampler.run`` to its at-rest stop (check=False).

    python benchmarks/bench_scale.py [--sizes 1e4,3e4,1e5,1e6] [--methods fan2d,...] [--quick] [--no-quality]
    python benchmarks/bench_scale.py --figure          # the docs figure from the JSON

Writes ``benchmarks/results/bench_scale.json`` (``--out``) with the load average before and after; prints progress
with tqdm.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

try:
    from _provenance import git_version, machine, write_json
except ImportError:
    from benchmarks._provenance import git_version, machine, write_json

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
OUT = HERE / "results" / "bench_scale.json"
FIGURE = ROOT / "docs" / "_static" / "bench_scale.png"
METHODS = ("fan2d", "fan3d", "bipi2d", "bipi3d", "alaric2d", "alaric3d", "parvi2d")
DIM = dict(fan2d=2, fan3d=3, bipi2d=2, bipi3d=3, alaric2d=2, alaric3d=3, parvi2d=2)
GOAL_BYTES = {2: 600, 3: 900}
GOAL_EXPONENT = 1.1
QUALITY_FAN = 6e-4
# the cheap ones (time to quality at 3e3, measured before choosing: SPH-ParVI 82 s / 9820 steps, BIPI 2D 11 s)
QUALITY_RUNS = "fan2d:1e4,fan2d:3e4,fan3d:1e4,bipi2d:1e4,alaric2d:1e4,alaric3d:1e4,parvi2d:1e3"
BUNNY = ROOT / "ase_sphrelax" / "data" / "bunny.edges"


# ----------------------------------------------------------------------------------------- the child process ---
def _status(key):
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(key):
                return int(line.split()[1]) * 1024
    raise KeyError(key)


def _torus():
    import trimesh

    return trimesh.creation.torus(major_radius=0.3, minor_radius=0.12, major_sections=48, minor_sections=24)


def _bunny_area():
    seg = np.loadtxt(BUNNY)
    return abs(0.5 * float(np.sum(seg[:, 0] * seg[:, 3] - seg[:, 2] * seg[:, 1])))


class _Clock:
    """Wall and CPU times of each step (an ASE observer)."""

    def __init__(self):
        self.wall, self.cpu = [time.perf_counter()], [time.process_time()]

    def __call__(self):
        self.wall.append(time.perf_counter())
        self.cpu.append(time.process_time())

    def per_step(self):
        w, c = np.diff(self.wall)[1:], np.diff(self.cpu)[1:]  # the first step builds the lists
        return float(np.median(w)), float(np.median(c)), len(self.wall) - 1


def _uniform(x):
    return np.ones(len(x))


def _no_gradient(x):
    return np.zeros_like(x)


def _fan_scene(dim, n):
    """Fan's circle / sphere (radius 0.2) filled at the spacing that holds about ``n``: (domain, dx, atoms)."""
    from ase_sphrelax.build import fill
    from ase_sphrelax.domains import Circle, Sphere

    r = 0.2
    domain = Circle((0.5, 0.5), r) if dim == 2 else Sphere((0.5, 0.5, 0.5), r)
    size = np.pi * r * r if dim == 2 else 4.0 / 3.0 * np.pi * r**3
    dx = (size / n) ** (1.0 / dim)
    return domain, dx, fill(domain, dx, jitter=0.1, seed=0)


def _bipi_scene(dim, n):
    """BIPI's bunny (2D) / torus mesh (3D) with its Step-1 fill of about ``n``: (boundary, dx, atoms)."""
    from ase_sphrelax.boundary import BoundarySegments, BoundaryTriangles
    from ase_sphrelax.drivers.bipi_packer import initial_fill

    if dim == 2:
        seg, size = BoundarySegments.from_edges(BUNNY), _bunny_area()
    else:
        mesh = _torus()
        seg, size = BoundaryTriangles.from_trimesh(mesh), float(mesh.volume)
    dx = float((size / n) ** (1.0 / dim))
    return seg, dx, initial_fill(seg, dx)


def _alaric_domain(dim, n):
    """The disc / ball centred at 0 that holds ``n`` particles at unit spacing."""
    from ase_sphrelax.domains import Circle, Sphere

    radius = (n / np.pi) ** 0.5 if dim == 2 else (3 * n / (4 * np.pi)) ** (1 / 3)
    return Circle((0.0, 0.0), radius) if dim == 2 else Sphere((0.0, 0.0, 0.0), radius)


def alaric_dynamics(atoms, dim, domain):
    """The bench's ALARIC: a uniform target in ``domain`` (the boundary its "auto" choice), its calculator attached
    to ``atoms``, and the dynamics without its stops."""
    from ase_sphrelax import ALARICCalculator
    from ase_sphrelax.drivers.alaric_dynamics import ALARICDynamics
    from ase_sphrelax.models.alaric import resolve_boundary

    atoms.calc = ALARICCalculator(target_density=_uniform, target_gradient=_no_gradient, dim=dim, domain=domain,
                                  boundary=resolve_boundary("auto", domain))
    return ALARICDynamics(atoms, eps_min=0.0, eps_dot_min=0.0)


def setup(method, n):
    """(start, run(steps) -> (wall, cpu, steps)) for ``method`` at about ``n`` particles. ``start`` is the system
    that counts in the baseline (Atoms, or positions for ParVI)."""
    import warnings

    warnings.simplefilter("ignore")
    dim = DIM[method]
    if method.startswith("fan"):
        from ase_sphrelax import FanCalculator, make_optimizer

        domain, dx, atoms = _fan_scene(dim, n)

        def run(steps):
            atoms.calc = FanCalculator(h=2.6 * dx, dx=dx, domain=domain)
            opt = make_optimizer("fan", atoms)
            clock = _Clock()
            opt.attach(clock, interval=1)
            opt.run(fmax=0.0, steps=steps)
            return clock.per_step()
        return atoms, run
    if method.startswith("bipi"):
        from ase_sphrelax import BIPICalculator, BIPIPacker

        seg, dx, atoms = _bipi_scene(dim, n)

        def run(steps):
            calc = BIPICalculator.from_paper(2.0, dx, seg)  # its default: no stored list in 3D
            packer = BIPIPacker(atoms, calc, stages=("2b", "2c"), max_steps_2c=steps, window=10**9)
            clock = _Clock()
            for _ in packer.irun():
                clock()
            return clock.per_step()
        return atoms, run
    if method.startswith("alaric"):
        from ase_sphrelax.build import fill

        domain = _alaric_domain(dim, n)
        atoms = fill(domain, 1.0, jitter=0.1, seed=0)

        def run(steps):
            dyn = alaric_dynamics(atoms, dim, domain)
            clock = _Clock()
            dyn.attach(clock, interval=1)
            dyn.run(steps)
            return clock.per_step()
        return atoms, run
    if method == "parvi2d":
        from ase_sphrelax.sampling import ParVISampler, get_target

        target = get_target("gaussian")

        def run(steps):
            times = []
            for k in (2, 2 + steps):
                sampler = ParVISampler(target.log_density, target.score, dim=2, n=int(n), steps=k, check=False,
                                       seed=0)
                w, c = time.perf_counter(), time.process_time()
                sampler.run()
                times.append((time.perf_counter() - w, time.process_time() - c))
            return (times[1][0] - times[0][0]) / steps, (times[1][1] - times[0][1]) / steps, 2 + steps
        return None, run
    raise ValueError(f"method must be one of {METHODS}, got {method!r}")


def child_step(method, n, steps):
    """One size in this (fresh) process: a dict of its figures."""
    import numba

    numba.set_num_threads(1)
    # the torus at 3000 particles has none farther than h from the mesh: 3e4 reaches BIPI 3D's far-particle branch;
    # SPH-ParVI at 2000 and at 3e4 did not compile every loop its 1e5 run calls (that row then counted numba's
    # compilation: 612 B per particle and a negative time per step, cold cache)
    warm_n = 30000 if method == "bipi3d" else min(n, 1e5) if method == "parvi2d" else 2000 if DIM[method] == 2 else 3000
    _, warm = setup(method, warm_n)
    warm(3)  # compile or load every loop
    import gc

    from ase_sphrelax import pairs
    from ase_sphrelax.neighbors import release_free_memory

    pairs._SCRATCH.clear()  # the pair loops' kept buffers of the warm-up's size: not in the baseline
    gc.collect()
    release_free_memory()
    start, run = setup(method, n)
    n_particles = len(start) if start is not None else int(n)
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")
    base = _status("VmRSS")
    t0 = time.perf_counter()
    wall, cpu, done = run(steps)
    return dict(method=method, n_target=n, n=n_particles, steps=done, wall_per_step=wall, cpu_per_step=cpu,
                wall_total=time.perf_counter() - t0, base_rss=base, peak_rss=_status("VmHWM"),
                bytes_per_particle=(_status("VmHWM") - base) / n_particles)


def child_quality(method, n, cap):
    """Wall time and steps of ``method`` to its stated quality at ``n`` (see the module docstring)."""
    import warnings

    import numba

    warnings.simplefilter("ignore")
    numba.set_num_threads(1)
    dim = DIM[method]
    _, warm = setup(method, 2000)
    warm(3)
    if method.startswith("fan"):
        from ase_sphrelax import FanCalculator, make_optimizer
        from ase_sphrelax.analysis.quality import quality_summary

        domain, dx, atoms = _fan_scene(dim, n)
        atoms.calc = FanCalculator(h=2.6 * dx, dx=dx, domain=domain)
        opt = make_optimizer("fan", atoms)
        t0, steps, err, timed = time.perf_counter(), 0, np.inf, 0.0
        while err > QUALITY_FAN and timed < cap:
            w = time.perf_counter()
            opt.run(fmax=0.0, steps=25)
            timed += time.perf_counter() - w
            steps += 25
            err = quality_summary(atoms, 2.6 * dx, dx, domain)["gradient_error_mean"]
        return dict(method=method, n=len(atoms), quality=f"interior mean h|sum V grad W| <= {QUALITY_FAN}",
                    reached=bool(err <= QUALITY_FAN), value=float(err), steps=steps, wall=timed,
                    wall_with_checks=time.perf_counter() - t0)
    if method.startswith("bipi"):
        from ase_sphrelax import BIPICalculator, BIPIPacker

        seg, dx, atoms = _bipi_scene(dim, n)
        packer = BIPIPacker(atoms, BIPICalculator.from_paper(2.0, dx, seg))
        t0, steps = time.perf_counter(), 0
        for _ in packer.irun():
            steps += 1
            if time.perf_counter() - t0 > cap:
                break
        wall = time.perf_counter() - t0
        return dict(method=method, n=len(atoms), quality="BIPIPacker's own stop (tol 0.01 over its window)",
                    reached=packer.stage == "done", verdict=str(packer.verdict())[:300], steps=steps, wall=wall)
    if method.startswith("alaric"):
        from ase_sphrelax.build import fill
        from ase_sphrelax.drivers.alaric_dynamics import relax_density
        from ase_sphrelax.splitting import SPLIT_COUNT

        out = dict(method=method, quality="relax_density's epsilon-dot stop (1e-8)")
        domain = _alaric_domain(dim, n)
        for route, splits in (("direct", 0), ("split", 1)):
            dx = 1.0 if not splits else SPLIT_COUNT[dim] ** (1.0 / dim)
            atoms = fill(domain, dx, jitter=0.1, seed=0)
            n_start = len(atoms)
            res = relax_density(atoms, _uniform, dim, target_gradient=_no_gradient, splits=splits, domain=domain,
                                max_steps=20000, max_wall=cap)
            stages = {}
            for e in res["trace"]:
                stages.setdefault(str(e.get("stage")), []).append(int(e["step"]))
            out[route] = dict(n_start=n_start, n=len(res["atoms"]), steps=int(res["steps"]),
                              steps_per_stage={k: max(v) - min(v) for k, v in stages.items()},
                              wall=float(res["wall_time"]), epsilon=float(res["epsilon"]),
                              stop_reason=res["stop_reason"], reached=bool(res["stop_reason"] in ("epsilon",
                                                                                              "epsilon_dot")))
        return out
    if method == "parvi2d":
        from ase_sphrelax.sampling import ParVISampler, get_target

        target = get_target("gaussian")
        sampler = ParVISampler(target.log_density, target.score, dim=2, n=int(n), check=False, seed=0)
        t0 = time.perf_counter()
        res = sampler.run()
        info = getattr(res, "info", {}) or {}
        return dict(method=method, n=int(n), quality="ParVISampler's at-rest stop (check=False)",
                    reached=bool(info.get("at_rest", info.get("converged"))), steps=info.get("steps"),
                    wall=time.perf_counter() - t0)
    raise ValueError(f"method must be one of {METHODS}, got {method!r}")


# ------------------------------------------------------------------------------------------------ the parent ---
def _child(args, timeout):
    env = dict(os.environ, NUMBA_NUM_THREADS="1", OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    out = subprocess.run([sys.executable, str(Path(__file__).resolve()), *args], env=env, capture_output=True,
                         text=True, timeout=timeout)
    if out.returncode:
        return dict(error=out.stderr.strip().splitlines()[-1] if out.stderr.strip() else f"exit {out.returncode}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def fit(n, t):
    return float(np.polyfit(np.log(n), np.log(t), 1)[0]) if len(n) > 1 else None


def parse_sizes(text):
    return [float(s) for s in text.split(",") if s]


def figure(result, path=FIGURE):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from ase_sphrelax.plotting import save_figure

    fig, axes = plt.subplots(1, 2, figsize=(9, 3.6))
    for k, (method, entry) in enumerate(result["methods"].items()):
        rows = [r for r in entry["rows"] if "error" not in r]
        if not rows:
            continue
        n = np.array([r["n"] for r in rows], float)
        style = dict(marker="os^v<>D"[k % 7], ls="-" if DIM[method] == 2 else "--", label=method)
        axes[0].loglog(n, [r["cpu_per_step"] for r in rows], **style)
        axes[1].loglog(n, [r["bytes_per_particle"] for r in rows], **style)
    axes[0].set(xlabel="N", ylabel="CPU time per step (s, 1 thread)", title="time per step")
    axes[1].set(xlabel="N", ylabel="peak RSS - baseline (B / particle)", title="memory (lines: 600 B 2D, 900 B 3D)")
    for dim, goal in GOAL_BYTES.items():
        axes[1].axhline(goal, color="grey", lw=0.8, ls="-" if dim == 2 else "--")
    axes[0].legend(fontsize=7, ncol=2)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    save_figure(fig, path, dpi=90, colors=64)
    print(f"wrote {path} ({path.stat().st_size // 1024} KB)")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--sizes", default="1e4,3e4,1e5,1e6", help="comma-separated N")
    parser.add_argument("--methods", default=",".join(METHODS))
    parser.add_argument("--quick", action="store_true", help="N = 1e3, 3e3, 1e4; quality at 1e3 capped at 3 s")
    parser.add_argument("--steps", type=int, default=5, help="steps timed per size (the first one dropped)")
    parser.add_argument("--max-step-1e6", type=float, default=40.0,
                        help="run 1e6 only when 10x the 1e5 wall time per step is below this (s)")
    parser.add_argument("--quality-runs", default=QUALITY_RUNS,
                        help="METHOD:N,... quality runs (only those of --methods; --quick: each method at 1e3)")
    parser.add_argument("--quality-cap", type=float, default=60.0, help="wall-time cap of a quality run (s)")
    parser.add_argument("--no-quality", dest="quality", action="store_false")
    parser.add_argument("--timeout", type=float, default=600.0, help="per child process (s)")
    parser.add_argument("--out", default=str(OUT))
    parser.add_argument("--figure", action="store_true", help="only redraw the figure from --out")
    parser.add_argument("--child", nargs=3, metavar=("KIND", "METHOD", "N"), help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        kind, method, n = args.child
        row = (child_step(method, float(n), args.steps) if kind == "step"
               else child_quality(method, float(n), args.quality_cap))
        print(json.dumps(row))
        return row
    if args.figure:
        figure(json.loads(Path(args.out).read_text()))
        return None
    from tqdm import tqdm

    sizes = [1e3, 3e3, 1e4] if args.quick else parse_sizes(args.sizes)
    if args.quick:
        args.quality_cap = min(args.quality_cap, 3.0)
    pairs = [(m, float(n)) for m, n in (item.split(":") for item in args.quality_runs.split(",") if item)]
    methods = [m for m in args.methods.split(",") if m]
    for m in methods:
        if m not in METHODS:
            raise SystemExit(f"--methods: unknown method {m!r}; choose from {','.join(METHODS)}")
    load_start = os.getloadavg()
    print(f"load average {load_start}", flush=True)
    result = dict(version=git_version(), machine=machine(), started=time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
                  load_average_start=load_start, threads=1, steps_per_size=args.steps,
                  time="median over the steps after the first, one numba thread, fresh process per size",
                  memory="peak RSS (VmHWM) - RSS after the start was built, per particle, fresh process per size",
                  goals=dict(exponent=GOAL_EXPONENT, bytes_per_particle_2d=GOAL_BYTES[2],
                             bytes_per_particle_3d=GOAL_BYTES[3]),
                  sizes=sizes, methods={})
    jobs = [(m, n) for m in methods for n in sizes]
    bar = tqdm(total=len(jobs), desc="bench_scale", unit="run")
    for method in methods:
        rows, skipped = [], []
        for n in sizes:
            bar.set_postfix_str(f"{method} N={n:.0e}")
            below = [r for r in rows if "error" not in r and r["n"] < n]
            if n >= 1e6 and below:
                last = below[-1]
                guess = last["wall_per_step"] * n / last["n"]
                if guess > args.max_step_1e6:
                    skipped.append(dict(n_target=n, reason=f"one step extrapolated from N={last['n']} to "
                                                           f"{guess:.1f} s > {args.max_step_1e6} s"))
                    bar.update()
                    continue
            try:
                row = _child(["--steps", str(args.steps), "--child", "step", method, repr(n)], args.timeout)
            except subprocess.TimeoutExpired:
                row = dict(n_target=n, error=f"timeout {args.timeout} s")
            row.setdefault("n_target", n)
            rows.append(row)
            bar.update()
            if "error" in row:
                tqdm.write(f"{method} N={n:.0e}: {row['error']}")
            else:
                tqdm.write(f"{method} N={row['n']:8d}: {row['wall_per_step'] * 1e3:9.2f} ms/step wall "
                           f"({row['cpu_per_step'] * 1e3:9.2f} CPU), {row['bytes_per_particle']:6.0f} B/particle")
        ok = [r for r in rows if "error" not in r]
        dim = DIM[method]
        entry = dict(dim=dim, rows=rows, not_measured=skipped,
                     exponent_cpu=fit([r["n"] for r in ok], [r["cpu_per_step"] for r in ok]),
                     exponent_wall=fit([r["n"] for r in ok], [r["wall_per_step"] for r in ok]),
                     bytes_per_particle_max=max((r["bytes_per_particle"] for r in ok), default=None),
                     n_max=max((r["n"] for r in ok), default=None))
        entry["meets_exponent"] = entry["exponent_cpu"] is not None and entry["exponent_cpu"] <= GOAL_EXPONENT
        entry["meets_memory"] = (entry["bytes_per_particle_max"] is not None
                                 and entry["bytes_per_particle_max"] <= GOAL_BYTES[dim])
        result["methods"][method] = entry
    bar.close()
    if args.quality:
        qjobs = [(m, 1e3) for m in methods] if args.quick else [(m, n) for m, n in pairs if m in methods]
        for method, n in tqdm(qjobs, desc="quality", unit="run"):
            try:
                row = _child(["--quality-cap", str(args.quality_cap), "--child", "quality", method, repr(n)],
                             args.timeout)
            except subprocess.TimeoutExpired:
                row = dict(error=f"timeout {args.timeout} s")
            row["n_target"] = n
            result["methods"][method].setdefault("quality", []).append(row)
            tqdm.write(f"quality {method} N={n:.0e}: {json.dumps(row)[:300]}")
    for method, entry in result["methods"].items():
        print(f"{method}: exponent (CPU per step) {entry['exponent_cpu']}, max {entry['bytes_per_particle_max']} "
              f"B/particle up to N={entry['n_max']}; not measured: {entry['not_measured']}")
    result["load_average_end"] = os.getloadavg()
    print(f"load average {result['load_average_end']}")
    write_json(args.out, result)
    return result


if __name__ == "__main__":
    main()
