"""Steps to the target (interior mean h|sum V grad W| <= 6e-4) on Fan's circle at 3e4 particles, per optimiser setting.

    python reproductions/speed-fan-1e6/scan_steps.py [--n 3e4] [--max-steps 500]

The same start as ``benchmarks/bench_fan_1e6.py`` at a smaller N (``fill(Circle((0.5, 0.5), 0.2),
0.000354 sqrt(1e6 / n), jitter=0.1, seed=0)``, h = 2.6 dx), the measure of ``quality_summary`` every 5 steps.
Settings: ``make_optimizer("fire")`` as it is and with FIRE's ``dtmax`` (in units of its first dt), ``Nmin``
and ``alpha`` changed one at a time; LAMMPS's FIRE parameters in ASE's FIRE; LBFGS (memory 5 and 20); Eq. 2.4
(c 0.01 and 0.02). Writes ``results/steps_scan.json`` beside this script: per setting the first step at or
below 2e-3, 1e-3 and 6e-4 (None: not within ``--max-steps``) and the measure every 5 steps.
"""
from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np

SETTINGS = {
    "fire (default)": ("fire", {}, {}),
    "fire dtmax 3 dt": ("fire", {}, {"dtmax": 3}),
    "fire dtmax 5 dt": ("fire", {}, {"dtmax": 5}),
    "fire Nmin 20": ("fire", {}, {"Nmin": 20}),
    "fire alpha 0.25": ("fire", {}, {"a": 0.25, "astart": 0.25}),
    "fire with LAMMPS's parameters": ("fire-lammps", {}, {}),
    "lbfgs (default, memory 5)": ("lbfgs", {}, {}),
    "lbfgs memory 20": ("lbfgs", {"memory": 20}, {}),
    "Eq. 2.4 c 0.01": ("fan", {}, {}),
    "Eq. 2.4 c 0.02": ("fan", {"c": 0.02}, {}),
}


def main(argv=None):
    from ase_sphrelax import FanCalculator, make_optimizer
    from ase_sphrelax.analysis.quality import quality_summary
    from ase_sphrelax.build import fill
    from ase_sphrelax.domains import Circle

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=float, default=3e4)
    parser.add_argument("--max-steps", type=int, default=500)
    parser.add_argument("--out", type=Path, default=Path(__file__).resolve().parent / "results" / "steps_scan.json")
    args = parser.parse_args(argv)
    dx = 0.000354 * math.sqrt(1e6 / args.n)
    h = 2.6 * dx
    domain = Circle((0.5, 0.5), 0.2)
    start = fill(domain, dx, jitter=0.1, seed=0)
    out = dict(n=len(start), dx=dx, h=h, max_steps=args.max_steps, settings={})
    for label, (name, kwargs, post) in SETTINGS.items():
        atoms = start.copy()
        atoms.calc = FanCalculator(h=h, dx=dx, domain=domain)
        if name == "fire-lammps":  # as benchmarks/bench_relax_lammps.py: LAMMPS's min_style fire defaults
            from lammps_io.relaxation import default_timestep

            dt = default_timestep(h, dx**2, 2)
            opt = make_optimizer("fire", atoms, dt=dt, dtmax=10 * dt, maxstep=0.1 * math.sqrt(len(atoms)), Nmin=20,
                                 a=0.25, astart=0.25, fa=0.99, finc=1.1, fdec=0.5)
        else:
            opt = make_optimizer(name, atoms, **kwargs)
        for key, value in post.items():
            setattr(opt, key, value * opt.dt if key == "dtmax" else value)
        trace = []
        for _ in range(0, args.max_steps, 5):
            opt.run(steps=5, fmax=0.0)
            trace.append(float(quality_summary(atoms, h, dx, domain)["gradient_error_mean"]))
            if trace[-1] <= 6e-4:
                break
        errors = np.array(trace)

        def first(level):
            return int(5 * (np.argmax(errors <= level) + 1)) if (errors <= level).any() else None

        out["settings"][label] = dict(first_2e3=first(2e-3), first_1e3=first(1e-3), first_6e4=first(6e-4),
                                      trace=trace)
        print(f"{label}: 2e-3 at {first(2e-3)}, 1e-3 at {first(1e-3)}, 6e-4 at {first(6e-4)}", flush=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(out, indent=1) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
