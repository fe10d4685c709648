"""Where one ALARIC step with mirror ghosts spends its time (issue 20 item 2): Fig. 13 (uniform density, 2000
particles, the unit circle, the random start of reproductions/lib/alaric_fig13_forms.py) or Fig. 8 in 3D (Eq. 46, Delta =
0.01, the unit ball, the CLI's start), profiled after ``--warm`` steps over ``--steps`` steps.

    python reproductions/alaric-fig13/profile.py --case fig13 --warm 50 --steps 300 --json FILE --key NAME

Reports ms per step, neighbour-list builds, density passes per H solve, ghosts, and the profiled time split into:
the H solve's density passes (power sums), list builds (fused with a density pass), pressure forces, viscosity,
the ghosts (images, the ghost set, folding their forces back) and the rest (Python, numpy). Run it with
``PYTHONPATH`` at another checkout to compare two versions in one session.
"""
from __future__ import annotations

import argparse
import cProfile
import json
import os
import pstats
import sys
import time
from pathlib import Path

import numpy as np

import ase_sphrelax
from ase_sphrelax import ALARICCalculator, sph
from ase_sphrelax.drivers.alaric_dynamics import ALARICDynamics, start_atoms
from ase_sphrelax.models.alaric import eq46

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from lib.alaric_reproduce import circle_start, uniform_density  # noqa: E402

# profiled functions by category (substring of "file:function" in cProfile's table, own time)
CATEGORIES = {
    "density passes (H solve)": ("_list_sym_3d_051ecc17___power_pair", "_smoothing_length_chunk", "_moments_from"),
    "list builds (fused with a density pass)": ("_build_sym", "neighbors.py:_build", "_bin_sort", "BinnedPoints"),
    "pressure forces": ("pressure_pair",),
    "viscosity": ("viscosity_pair",),
    "ghosts (images, set, fold)": ("mirror_images", "_ball_images", "mirror_map", "_radial_hits", "needed_ghosts",
                                   "_ghost_owners", "_fold_ghosts", "_solve_with_ghosts"),
}


def make(case, n):
    if case == "fig13":
        from ase_sphrelax.domains import Circle

        atoms = circle_start(n, 0)
        calc = ALARICCalculator(target_density=uniform_density, target_gradient=lambda x: np.zeros_like(x), dim=2,
                                domain=Circle((0.0, 0.0), 1.0), boundary="mirror", form="log")
    else:
        atoms, _, domain = start_atoms(n, 3, seed=0)
        density, gradient = eq46(0.01)
        calc = ALARICCalculator(target_density=density, target_gradient=gradient, dim=3, domain=domain,
                                boundary="mirror", form="log")
    atoms.calc = calc
    return atoms, calc


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--case", choices=("fig13", "fig8_3d"), default="fig13")
    ap.add_argument("--n", type=int, default=2000)
    ap.add_argument("--warm", type=int, default=50)
    ap.add_argument("--steps", type=int, default=300)
    ap.add_argument("--json", default=None)
    ap.add_argument("--key", default=None)
    args = ap.parse_args()
    passes = dict(solves=0, passes=0)
    solve = sph.solve_smoothing_lengths

    def counted(*a, **k):
        out = solve(*a, **k)
        passes["solves"] += 1
        passes["passes"] += out.iterations
        return out

    sph.solve_smoothing_lengths = counted
    small, _ = make(args.case, 200 if args.case == "fig13" else 400)  # numba compiles outside the timing
    ALARICDynamics(small, eps_dot_min=0.0, eps_min=0.0).run(3)
    atoms, calc = make(args.case, args.n)
    dyn = ALARICDynamics(atoms, eps_dot_min=0.0, eps_min=0.0)
    dyn.run(args.warm)
    builds0 = calc.nlist.builds
    passes.update(solves=0, passes=0)
    load0 = os.getloadavg()
    prof = cProfile.Profile()
    t0 = time.perf_counter()
    prof.enable()
    dyn.run(args.steps)
    prof.disable()
    wall = time.perf_counter() - t0
    stats = pstats.Stats(prof).stats
    total = sum(v[2] for v in stats.values())  # own times
    split = {name: 0.0 for name in CATEGORIES}
    for (path, _, func), v in stats.items():
        label = f"{os.path.basename(path)}:{func}"
        for name, keys in CATEGORIES.items():
            if any(k in label for k in keys):
                split[name] += v[2]
                break
    split["rest (Python, numpy, ASE)"] = total - sum(split.values())
    row = dict(package=str(Path(ase_sphrelax.__file__).parent), case=args.case, n=args.n, warm=args.warm,
               steps=args.steps, ms_per_step=1e3 * wall / args.steps, nlist_builds=calc.nlist.builds - builds0,
               density_passes_per_solve=passes["passes"] / max(passes["solves"], 1),
               ghosts=int(len(calc._ghosts[0])), epsilon=float(calc.results["epsilon"]),
               ms_per_step_by_part={k: 1e3 * v / args.steps for k, v in split.items()},
               profiled_ms_per_step=1e3 * total / args.steps, load_average_start=load0,
               load_average_end=os.getloadavg(), threads=os.environ.get("NUMBA_NUM_THREADS", "unset"))
    print(json.dumps(row, indent=1))
    if args.json:
        path = Path(args.json)
        table = json.loads(path.read_text()) if path.exists() else {}
        table[args.key or f"{args.case}_{args.n}"] = row
        path.write_text(json.dumps(table, indent=1))


if __name__ == "__main__":
    main()
