"""A first run with numba's cache empty, as after installing: ``sphrelax relax`` on the default scene (``relax``)
and BIPI's ``sphrelax pack`` on a closed triangle mesh (``pack3d``: an icosphere of 320 triangles, 3 iterations of
each stage).

Each run is a fresh process with ``NUMBA_CACHE_DIR`` set to an empty directory, so every jitted function it calls is
compiled. Recorded per run: the whole command's wall time, the relaxation's own (the CLI's "wall time" line), the
sum of numba's compile events and the functions that took longest to compile (nested compilations counted in their
callers too). ``--steps`` shortens the relaxation (5 by default: the compilation is the same). ``--baseline-root``
times another checkout the same way in the same session (e.g. a ``git worktree`` of an older commit), runs
alternating.

    python benchmarks/bench_cold_start.py --repeats 2 --scenes relax,pack3d --baseline-root /tmp/wt_old \
        --out benchmarks/results/bench_cold_start.json
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

# run in the timed process: numba's compile events, summed by function, written as JSON to argv[1]
PROBE = r"""
import collections, json, sys, time
from numba.core import event

spent = collections.Counter()
class Compiles(event.Listener):
    def __init__(self):
        self.started = {}
    def on_start(self, ev):
        self.started[id(ev.data.get("dispatcher"))] = time.perf_counter()
    def on_end(self, ev):
        d = ev.data.get("dispatcher")
        t0 = self.started.pop(id(d), None)
        if t0 is not None:
            spent[getattr(d, "__qualname__", str(d))] += time.perf_counter() - t0
event.register("numba:compile", Compiles())
out = sys.argv[1]
sys.argv = ["sphrelax"] + sys.argv[2:]
from ase_sphrelax.cli.main import main
try:
    main()
finally:
    top = [[name, round(t, 2)] for name, t in spent.most_common(8)]
    with open(out, "w") as f:
        json.dump(dict(top=top), f)
"""


def command(scene, work, steps):
    """The ``sphrelax`` arguments of ``scene``, its files written into ``work``."""
    out = ["--out", str(Path(work) / "out"), "--overwrite"]
    if scene == "relax":
        return ["relax", *out, "--steps", str(steps)]
    import trimesh

    mesh = trimesh.creation.icosphere(subdivisions=2, radius=0.3)
    mesh.apply_translation([0.5, 0.5, 0.5])
    mesh.export(Path(work) / "sphere.stl")
    return ["pack", "--boundary", str(Path(work) / "sphere.stl"), "--dx", "0.05", *out, "--max-steps-2a", "3",
            "--max-steps-2c", "3", "--no-progress"]


def one_run(root, scene, steps):
    """Whole-command time, relaxation time and compile events of one cold run of the checkout at ``root``."""
    with tempfile.TemporaryDirectory() as cache, tempfile.TemporaryDirectory() as work:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache, PYTHONPATH=str(root), MPLBACKEND="Agg")
        events = Path(work) / "events.json"
        t0 = time.perf_counter()
        done = subprocess.run([sys.executable, "-c", PROBE, str(events), *command(scene, work, steps)], env=env,
                              cwd=work, capture_output=True, text=True)
        wall = time.perf_counter() - t0
        if done.returncode:
            raise RuntimeError(f"sphrelax {scene} failed in {root}:\n{done.stderr[-2000:]}")
        relaxation = None
        for line in done.stdout.splitlines():
            if line.startswith("wall time: relaxation"):
                relaxation = float(line.split("relaxation")[1].split("s")[0])
        warnings = [line for line in done.stderr.splitlines() if "warning" in line.lower()
                    and "not converged" not in line]  # pack3d's iteration caps are given: it says so
        return dict(wall_time=wall, relaxation_time=relaxation, compiles=json.loads(events.read_text())["top"],
                    warnings=warnings)


def version(root):
    return subprocess.run(["git", "describe", "--always", "--dirty"], capture_output=True, text=True,
                          cwd=root).stdout.strip()


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeats", type=int, default=2, help="cold runs of each checkout (default 2)")
    parser.add_argument("--steps", type=int, default=5, help="relaxation steps of each relax run (default 5)")
    parser.add_argument("--scenes", default="relax", help="comma separated: relax, pack3d (default relax)")
    parser.add_argument("--baseline-root", type=Path, default=None, help="another checkout to time alongside")
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "bench_cold_start.json")
    args = parser.parse_args(argv)
    scenes = [s.strip() for s in args.scenes.split(",") if s.strip()]
    unknown = sorted(set(scenes) - {"relax", "pack3d"})
    if unknown or not scenes:
        parser.error(f"--scenes: unknown {unknown}; give relax and/or pack3d")
    roots = {"current": ROOT}
    if args.baseline_root is not None:
        roots["baseline"] = args.baseline_root.resolve()
    runs = {(scene, name): [] for scene in scenes for name in roots}
    load_start = os.getloadavg()
    for scene in scenes:
        for _ in range(args.repeats):
            for name, root in roots.items():
                run = one_run(root, scene, args.steps)
                runs[scene, name].append(run)
                print(f"{scene} {name} ({version(root)}): whole {run['wall_time']:.1f} s, relaxation "
                      f"{run['relaxation_time']} s, longest compile {run['compiles'][0] if run['compiles'] else None}, "
                      f"{len(run['warnings'])} warning line(s)")
    record = dict(steps=args.steps, repeats=args.repeats, scenes={},
                  load_average_start=load_start, load_average_end=os.getloadavg(),
                  command="python benchmarks/bench_cold_start.py " + " ".join(sys.argv[1:] if argv is None else argv))
    for scene in scenes:
        rec = record["scenes"][scene] = dict(checkouts={
            name: dict(version=version(root), runs=runs[scene, name],
                       wall_time_mean=sum(r["wall_time"] for r in runs[scene, name]) / len(runs[scene, name]))
            for name, root in roots.items()})
        if "baseline" in roots:
            rec["ratio_current_over_baseline"] = (rec["checkouts"]["current"]["wall_time_mean"]
                                                  / rec["checkouts"]["baseline"]["wall_time_mean"])
    print(f"load average {load_start[0]:.2f} at the start, {os.getloadavg()[0]:.2f} at the end")
    args.out.write_text(json.dumps(record, indent=1) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
