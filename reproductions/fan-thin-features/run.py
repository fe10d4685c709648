"""Fan's wall on a polygon: the polygon itself, or its opening at 0.35 dp (parts narrower than 0.7 dp left out)?

Issue 33, item 3 asks that no particle end nearer than 0.35 dx to a wall at corners and sharp tips, with the
near-wall kernel-sum error (the continuum completed beyond the wall) at most 0.05. At the shipped airfoil's 15 degree
trailing edge the default of f7b6758 (the exact-integral continuum of the polygon itself with its contact core) left
the nearest particle 0.309 dx from the wall, where the foil is 0.65 dx thick, and no stiffness of the core met both
goals (``reproductions/fan-cli-optimizer/core_stiffness.py``). No point of a part narrower than 0.7 dx is 0.35 dx from
both walls, yet the continuum pulls particles into it. The candidate: the wall of Fan's ``"gamma"`` term is the
polygon's morphological opening at ``r = 0.35 dp`` (``Polygon.opening``, ``FanModel.wall``): convex corners become
arcs of radius r, concave corners and straight walls stay, and the parts narrower than 2 r are left out.

The criteria, declared before the runs (the issue's two goals, and no loss inside):

1. with the opening, in every scene and seed: ``boundary_distance_min >= 0.35`` (dx, to the polygon itself),
   ``near_wall_kernel_sum_error_max <= 0.05`` (completed beyond the polygon itself) and no particle outside;
2. the interior ``gradient_error_mean``, averaged over the seeds, at most the polygon-itself route's average plus
   that route's spread over the seeds (max - min), in every scene.

The opening stays the default (``FanModel.wall_opening = WALL_OPENING``) only if both hold; ``verdict`` in
``summary.json`` says which. Scenes: the shipped ``airfoil.edges``, ``tank.edges`` and ``bunny.edges`` and the
chevron of ``reproductions/fan-cli-optimizer`` (28 and 53 degree tips, a concave corner), each as ``sphrelax relax
--domain FILE`` builds it (``make_scene``: dx = extent / 128, ``fill`` with jitter 0.1) for seeds 0, 1, 2, relaxed by
2000 steps of Eq. 2.4 (``make_optimizer("fan")``, the CLI's default) with each wall; all measures by
``quality_summary`` against the polygon itself. Then the radius: the airfoil and the chevron at seed 0 with
``r / dp`` of 0.3, 0.35, 0.4 and 0.5.

    python reproductions/fan-thin-features/run.py --out reproductions/fan-thin-features/results   # about 6 minutes
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from lib.fan_edge_scenes import edge_files  # noqa: E402

SCENES = ("airfoil", "chevron", "tank", "bunny")
SEEDS = (0, 1, 2)
RADII = (0.3, 0.35, 0.4, 0.5)
MEASURES = ("boundary_distance_min", "near_wall_kernel_sum_error_max", "n_outside", "gradient_error_mean",
            "gradient_error_max")


def scene_files(work):
    """Name -> the edge file of the scene, in the order of ``SCENES``."""
    out = edge_files(work)
    return {name: out[name] for name in SCENES}


def relax(path, seed, opening, steps):
    """One relaxation: the measures against the polygon itself, the particle count and the seconds."""
    from ase_sphrelax import FanCalculator
    from ase_sphrelax.analysis.quality import quality_summary
    from ase_sphrelax.cli.scene import make_scene
    from ase_sphrelax.drivers.optimizers import make_optimizer

    domain, dx, atoms = make_scene(str(path), seed=seed)
    h = 2.6 * dx
    atoms.calc = FanCalculator(h=h, dx=dx, domain=domain)
    atoms.calc.model.wall_opening = opening
    t0 = time.perf_counter()
    make_optimizer("fan", atoms).run(fmax=0.0, steps=steps)
    seconds = time.perf_counter() - t0
    atoms.set_constraint()
    q = quality_summary(atoms, h, dx=dx, domain=domain)
    wall = atoms.calc.model.wall(dx**2)[1]
    return dict(n=len(atoms), dx=dx, seconds=round(seconds, 2), left_out_dx2=(domain.volume - wall.volume) / dx**2,
                **{k: q[k] for k in MEASURES})


def verdict(rows):
    """The declared criteria (module docstring) per scene, and the decision."""
    out = {}
    for scene in SCENES:
        mine = [r for r in rows if r["scene"] == scene and r["route"] == "opening"]
        base = [r for r in rows if r["scene"] == scene and r["route"] == "polygon itself"]
        goals = all(r["boundary_distance_min"] >= 0.35 and r["near_wall_kernel_sum_error_max"] <= 0.05
                    and r["n_outside"] == 0 for r in mine)
        base_ge = [r["gradient_error_mean"] for r in base]
        inside = float(np.mean([r["gradient_error_mean"] for r in mine])) <= float(np.mean(base_ge)) + \
            (max(base_ge) - min(base_ge))
        base_goals = all(r["boundary_distance_min"] >= 0.35 and r["near_wall_kernel_sum_error_max"] <= 0.05
                         and r["n_outside"] == 0 for r in base)
        out[scene] = dict(opening_meets_goals=bool(goals), opening_not_worse_inside=bool(inside),
                          polygon_itself_meets_goals=bool(base_goals))
    out["opening_is_the_default"] = all(v["opening_meets_goals"] and v["opening_not_worse_inside"]
                                        for k, v in out.items() if k in SCENES)
    return out


def main(argv=None):
    from ase_sphrelax.models.fan import WALL_OPENING

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--steps", type=int, default=2000)
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    rows, radii = [], []
    with tempfile.TemporaryDirectory() as tmp:
        files = scene_files(Path(tmp))
        for scene, path in files.items():
            for seed in SEEDS:
                for route, opening in (("polygon itself", 0.0), ("opening", WALL_OPENING)):
                    row = dict(scene=scene, seed=seed, route=route, wall_opening=opening,
                               **relax(path, seed, opening, args.steps))
                    rows.append(row)
                    print({k: (round(v, 4) if isinstance(v, float) else v) for k, v in row.items()}, flush=True)
        for scene in ("airfoil", "chevron"):
            for radius in RADII:
                row = dict(scene=scene, seed=0, wall_opening=radius, **relax(files[scene], 0, radius, args.steps))
                radii.append(row)
                print({k: (round(v, 4) if isinstance(v, float) else v) for k, v in row.items()}, flush=True)
    summary = dict(command="python reproductions/fan-thin-features/run.py --out reproductions/fan-thin-features/results",
                   steps=args.steps, wall_opening_default=WALL_OPENING, rows=rows, radii=radii, verdict=verdict(rows))
    (args.out / "summary.json").write_text(json.dumps(summary, indent=1))
    print(json.dumps(summary["verdict"], indent=1))


if __name__ == "__main__":
    main()
