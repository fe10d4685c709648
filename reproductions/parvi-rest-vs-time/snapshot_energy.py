"""The model energy E = sum m u(rho) - alpha sum m log p (the Lyapunov function of the damped flow; its minima are
the resting states) of every checkpoint of the snapshot files given, evaluated with the default ParVIModel (the
physics of every variant run here: isothermal, alpha = c0^2 = 1, adaptive H, 32 neighbours in 2D).

    PYTHONPATH=. .venv/bin/python reproductions/parvi-rest-vs-time/snapshot_energy.py \\
        reproductions/parvi-rest-vs-time/results/snapshots/funnel_m500_s0_local_critical.npz ... \\
        --out reproductions/parvi-rest-vs-time/results/snapshot_energy.json
"""
import argparse
import json
from pathlib import Path

import numpy as np

from ase_sphrelax.models.parvi import ParVIModel
from ase_sphrelax.sampling import get_target
from ase_sphrelax.sampling.sampler import ParticleScoreMemory


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("files", nargs="+", type=Path)
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    rows = json.loads(args.out.read_text())["rows"] if args.out.exists() else []
    for path in args.files:
        data = np.load(path)
        target = get_target(path.name.split("_")[0])
        steps = sorted(int(k[2:]) for k in data.files if k.startswith("r_"))
        for step in steps:
            r_pc = data[f"r_{step}"]
            memory = ParticleScoreMemory(target.log_density, target.score, target.dim, n=len(r_pc))
            ev = ParVIModel(memory, target.dim).evaluate(r_pc, np.zeros_like(r_pc), want_energy=True)
            rows.append(dict(file=path.name, steps=step, energy=float(ev.energy),
                             residual_force_rms=float(np.sqrt(np.mean(np.sum(ev.forces**2, axis=1))) * len(r_pc))))
            print(json.dumps(rows[-1]), flush=True)
    args.out.write_text(json.dumps(dict(command="see snapshot_energy.py's docstring", rows=rows), indent=1))


if __name__ == "__main__":
    main()
