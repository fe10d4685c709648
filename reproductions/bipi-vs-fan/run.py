"""BIPI and Fan's relaxation side by side on the same shapes, dx, support h and starting fill (issue 7 item 7).

    python reproductions/bipi-vs-fan/run.py --out reproductions/bipi-vs-fan/results

Shapes: the trapezoid (dx = 0.02), the Stanford bunny (dx = 1 mm) and the fluid box around the airfoil
(dx = 0.25 in); h_B / dx = 2, i.e. support h = 4 dx for every method; start: BIPI's Step 1 (one particle
per cell centre, none within dx/8 of the boundary). Methods:

* ``bipi``: the paper's packer (Steps 2a-2c, 1 % rules over 10 iterations, caps 5000 / 1000);
* ``fan-eq2.4``: FanCalculator (Fan's Eq. 3.8 with the level set of the same polygon) and Eq. 2.4,
  c = 0.01, 2000 steps (Fan's Appendix A);
* ``fan-lbfgs``: the same energy with ASE's LBFGS through ``make_optimizer`` (1000 steps);
* ``ebi-fire``, ``ebi-lbfgs``: FIRE and LBFGS on BIPI's objective E_BI (BIPICalculator; 1000 steps).

Metrics (the same for every method): wall time, iterations (force evaluations), the shared metrics of
``analysis.quality`` (interior = support inside the domain: mean |sum_j V W_ij - 1|, its standard
deviation, mean h |sum_j V grad W_ij|; boundary layer mean distance / dx; particles outside) and
BIPI's |grad C|_avg over the particles beyond k_b = 0.6 dx (gamma above the wall value, the particles
Step 2b leaves free). Writes ``comparison.md`` and ``comparison.json``.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
import warnings
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # BLAS threads collapse under contention here (FACTS.md)
import numpy as np  # noqa: E402

GEOMETRIES = Path(__file__).resolve().parents[3] / "shared" / "geometries"
SHAPES = {"trapezoid": ("TrapezoidalTank", 0.02), "bunny": ("Standford2DBunny", 1.0),
          "airfoil_fluid": ("AirFoilFluid", 0.25)}
METHODS = ("bipi", "fan-eq2.4", "fan-lbfgs", "ebi-fire", "ebi-lbfgs")
H_OVER_DX = 4.0  # support; h_B / dx = 2


def bipi_metrics(atoms, boundary, dx, h):
    """|grad C|_avg (particles with gamma above the wall value at 0.6 dx) and the shared quality metrics."""
    from ase_sphrelax import BIPICalculator
    from ase_sphrelax.analysis import quality_summary

    calc = BIPICalculator(h=h, dx=dx, boundary=boundary)
    probe = atoms.copy()
    probe.set_constraint()
    probe.calc = calc
    gamma = calc.get_gamma(probe)
    free = gamma >= calc.model.wall_gamma(calc.model.k_b)
    out = {}
    if np.all(gamma > 0):
        grad = np.linalg.norm(calc.get_concentration_gradient(probe), axis=1)
        out["gradc_avg_free"] = float(grad[free].mean())
        out["gradc_avg_all"] = float(grad.mean())
    else:
        out["gradc_avg_free"] = out["gradc_avg_all"] = float("nan")
    q = quality_summary(probe, h, dx=dx, domain=boundary.domain)
    out.update({k: q[k] for k in ("kernel_sum_error_mean", "kernel_sum_std", "gradient_error_mean",
                                  "boundary_distance_mean", "n_outside", "n_particles")})
    return out


def run(method, boundary, dx, start):
    from ase_sphrelax import BIPICalculator, FanCalculator
    from ase_sphrelax.drivers import make_optimizer
    from ase_sphrelax.drivers.bipi_packer import BIPIPacker

    h = H_OVER_DX * dx
    atoms = start.copy()
    t = time.perf_counter()
    if method == "bipi":
        packer = BIPIPacker(atoms, BIPICalculator(h=h, dx=dx, boundary=boundary))
        packer.run()
        iterations = len(packer.history)
    else:
        if method.startswith("fan"):
            atoms.calc = FanCalculator(h=h, dx=dx, domain=boundary.domain,
                                       boundary_term="level_set")  # as stored (issue 33: the default is now "gamma")
        else:
            atoms.calc = BIPICalculator(h=h, dx=dx, boundary=boundary)
        name = {"fan-eq2.4": "fan", "fan-lbfgs": "lbfgs", "ebi-fire": "fire", "ebi-lbfgs": "lbfgs"}[method]
        steps = 2000 if method == "fan-eq2.4" else 1000
        opt = make_optimizer(name, atoms)
        opt.run(fmax=0.0 if name == "fan" else 1e-12, steps=steps)
        iterations = opt.nsteps
    wall = time.perf_counter() - t
    return atoms, dict(wall_time=wall, iterations=iterations)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="reproductions/bipi-vs-fan/results")
    parser.add_argument("--shapes", nargs="*", default=list(SHAPES), choices=list(SHAPES))
    parser.add_argument("--methods", nargs="*", default=list(METHODS), choices=METHODS)
    args = parser.parse_args(argv)
    if not GEOMETRIES.is_dir():
        sys.exit(f"{GEOMETRIES} not found")
    warnings.simplefilter("ignore", FutureWarning)
    from ase_sphrelax.boundary import BoundarySegments
    from ase_sphrelax.drivers.bipi_packer import initial_fill

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    path = out / "comparison.json"
    results = json.loads(path.read_text()) if path.exists() else {}
    for shape in args.shapes:
        geometry, dx = SHAPES[shape]
        boundary = BoundarySegments.from_edges(GEOMETRIES / f"{geometry}.edges")
        start = initial_fill(boundary, dx)
        h = H_OVER_DX * dx
        results.setdefault(shape, {})["start"] = dict(bipi_metrics(start, boundary, dx, h), wall_time=0.0,
                                                        iterations=0)
        for method in args.methods:
            print(f"== {shape} {method}", flush=True)
            atoms, row = run(method, boundary, dx, start)
            row.update(bipi_metrics(atoms, boundary, dx, h))
            results[shape][method] = row
            print("   " + ", ".join(f"{k}={v:.4g}" for k, v in row.items()), flush=True)
            path.write_text(json.dumps(results, indent=1))
    lines = ["| shape (N) | method | wall s | iterations | mean abs(ΣVW−1) | std ΣVW | mean h·abs(ΣV∇W) | "
             "abs(∇C) avg (beyond 0.6 dx) | layer d/dx | outside |", "|" + "---|" * 10]
    for shape, rows in results.items():
        for method in ("start",) + METHODS:
            if method not in rows:
                continue
            r = rows[method]
            lines.append(f"| {shape} ({r['n_particles']}) | {method} | {r['wall_time']:.1f} | {r['iterations']} | "
                         f"{r['kernel_sum_error_mean']:.2e} | {r['kernel_sum_std']:.2e} | {r['gradient_error_mean']:.2e} | "
                         f"{r['gradc_avg_free']:.2e} | {r['boundary_distance_mean']:.3f} | {r['n_outside']} |")
    (out / "comparison.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
