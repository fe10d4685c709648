"""FIRE's steps to the bench's target on Fan's sphere (``benchmarks/bench_fan_1e6.py``'s 3D start and measure, the
measure taken after every step from the step's own forces) for settings around ``make_optimizer("fire")``'s
defaults: whether a FIRE setting takes fewer steps in 3D (the 30 s goal needs about a third fewer). Step counts, not
times: any load.

    NUMBA_NUM_THREADS=1 python reproductions/speed-fan-1e6/fire_scan_3d.py --sizes 1e4,1e5 \
        --out reproductions/speed-fan-1e6/results/fire_scan_3d.json
"""
import argparse
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))

SETTINGS = {
    "default": {},
    "a 0.1": dict(a=0.1, astart=0.1),
    "a 0.12": dict(a=0.12, astart=0.12),
    "dtmax 2 dt": dict(dtmax_over_dt=2.0),
    "a 0.1, dtmax 2 dt": dict(a=0.1, astart=0.1, dtmax_over_dt=2.0),
    "c 0.005": dict(c=0.005),
}


def steps_to_target(n, setting, target=6e-4, max_steps=400):
    """First step at or below ``target`` (None if not within ``max_steps``) and the measure there."""
    import bench_fan_1e6 as bf

    from ase_sphrelax import FanCalculator, make_optimizer

    domain, dx, atoms = bf.scene(3, n)
    h = bf.RATIO * dx
    atoms.calc = FanCalculator(h=h, dx=dx, domain=domain)
    kwargs = dict(setting)
    c = kwargs.pop("c", None)
    ratio = kwargs.pop("dtmax_over_dt", None)
    opt = make_optimizer("fire", atoms, c=c, **kwargs)
    if ratio is not None:
        opt.dtmax = ratio * opt.dt
    v0 = dx**3
    measure = None
    for _ in opt.irun(fmax=0.0, steps=max_steps):
        interior = domain.phi(atoms.positions) <= -h
        measure = h / (2.0 * v0) * float(np.linalg.norm(atoms.calc.results["forces"][interior], axis=1).mean())
        if measure <= target:
            return int(opt.nsteps), measure, len(atoms)
    return None, measure, len(atoms)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--sizes", default="1e4,1e5")
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args(argv)
    rows = []
    for n in [float(s) for s in args.sizes.split(",")]:
        for label, setting in SETTINGS.items():
            steps, measure, count = steps_to_target(n, setting)
            rows.append(dict(n=count, setting=label, parameters=setting, steps=steps, measure=measure))
            print(json.dumps(rows[-1]), flush=True)
    version = subprocess.run(["git", "describe", "--always", "--dirty"], capture_output=True, text=True,
                             cwd=ROOT).stdout.strip()
    args.out.write_text(json.dumps(dict(version=version, target=6e-4, rows=rows, command="NUMBA_NUM_THREADS=1 python "
                                        "reproductions/speed-fan-1e6/fire_scan_3d.py " + " ".join(argv or sys.argv[1:])),
                                   indent=1) + "\n")


if __name__ == "__main__":
    main()
