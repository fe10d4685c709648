"""Fig. 8 in 2D: does a particle stay at the bottom of Eq. 46's well? One ingredient at a time.

Eq. 46 with Delta = 0.01 in the unit disc (mirror ghosts at the edge), N particles (N/4 split once, the CLI's
jittered-lattice start). Runs: the start as it is, and the same start with the particle closest to the centre
moved to r = 0 (the split keeps the parent's position for its central child, Fig. 2); each with the log potential
alone and with the least-squares finish. Recorded: epsilon (Eq. 45), the particle closest to the centre at the
end, the smallest nearest-neighbour distance over the mean, steps and wall time.

    python reproductions/alaric-fig8-bottom/run.py --n 1000 --max-steps 3000 --out reproductions/alaric-fig8-bottom/results
"""
from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from ase_sphrelax.analysis.alaric import alaric_min_error
from ase_sphrelax.drivers.alaric_dynamics import relax_density, start_atoms
from ase_sphrelax.models import alaric as model


def run(n, max_steps, centred, finish, delta=0.01):
    atoms, origin, domain = start_atoms(n // 4, 2)
    if centred:
        k = int(np.argmin(np.linalg.norm(atoms.positions[:, :2], axis=1)))
        atoms.positions[k, :2] = 0.0
    density, gradient = model.eq46(delta)
    t0 = time.perf_counter()
    res = relax_density(atoms, density, 2, target_gradient=gradient, splits=1, domain=domain, origin=origin,
                        polish=False, max_steps=max_steps, finish=finish, form="log")
    x = res["atoms"].positions[:, :2]
    gap = cKDTree(x).query(x, k=2)[0][:, 1]
    return dict(centred_start=centred, finish=finish, n=len(x), steps=res["steps"], stop=res["stop_reason"],
                epsilon=res["epsilon"], epsilon_teo_min=alaric_min_error(len(x), delta, 2),
                r_min=float(np.linalg.norm(x, axis=1).min()), nn_min_over_mean=float(gap.min() / gap.mean()),
                wall_s=time.perf_counter() - t0, boundary=res["calculator"].parameters.boundary)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1000)
    ap.add_argument("--max-steps", type=int, default=3000)
    ap.add_argument("--out", default="reproductions/alaric-fig8-bottom/results")
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    command = f"python reproductions/alaric-fig8-bottom/run.py --n {args.n} --max-steps {args.max_steps} --out {args.out}"
    rows = []
    for centred in (False, True):
        for finish in ("none", "squares"):
            rows.append(run(args.n, args.max_steps, centred, finish))
            print(rows[-1], flush=True)
    load = os.getloadavg()
    (out / "results.json").write_text(json.dumps(dict(command=command, load_average=load, runs=rows), indent=1))
    lines = [f"Eq. 46, Delta = 0.01, 2D unit disc (mirror ghosts), N = {rows[0]['n']}, step cap {args.max_steps}. "
             f"Command: `{command}`. Load average at the end {load[0]:.1f}.", "",
             "| start | finish | steps | stop | eps | Eq. 48 | closest particle to r = 0 | min NN / mean | wall s |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {'particle moved to r = 0' if r['centred_start'] else 'CLI default'} | {r['finish']} | "
                     f"{r['steps']} | {r['stop']} | {r['epsilon']:.2e} | {r['epsilon_teo_min']:.1e} | "
                     f"{r['r_min']:.3g} | {r['nn_min_over_mean']:.3f} | {r['wall_s']:.0f} |")
    (out / "table.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
