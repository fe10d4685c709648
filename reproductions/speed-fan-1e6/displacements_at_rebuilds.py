"""Who sets off the 3D list's rebuilds: at every rebuild of the bench's sphere run (``make_optimizer("fire")``, the
package's defaults, 170 steps), how many particles have moved more than half the skin since the list's build, the
99.9 % and 99 % quantiles of the displacements (in skins), and the largest displacement of one particle relative to
another within 1.3 h (in skins; a list check on relative displacements could only last longer where it is below
twice the largest displacement).

The question, declared before the run: are the rebuilds set off by a few fast particles (a handful beyond half the
skin, the 99.9 % quantile well below it), or by the bulk?

    NUMBA_NUM_THREADS=2 python reproductions/speed-fan-1e6/displacements_at_rebuilds.py 1e5 \
        reproductions/speed-fan-1e6/results/displacements_at_rebuilds_1e5.json
"""
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))

import bench_fan_1e6 as bf  # noqa: E402

import ase_sphrelax.neighbors as neighbors  # noqa: E402
from ase_sphrelax import FanCalculator, make_optimizer  # noqa: E402


def main(n=1e5, out=None, steps=170):
    domain, dx, atoms = bf.scene(3, n)
    calc = atoms.calc = FanCalculator(h=bf.RATIO * dx, dx=dx, domain=domain)
    h = calc.model.h
    opt = make_optimizer("fire", atoms)
    rows = []
    still_valid = neighbors.NeighborList._still_valid

    def observed(nlist, r_pc):
        valid = still_valid(nlist, r_pc)
        if not valid and nlist.stored and nlist.positions_at_build is not None \
                and nlist.positions_at_build.shape == r_pc.shape:
            moved_pc = r_pc - nlist.positions_at_build
            moved = np.sqrt((moved_pc ** 2).sum(axis=1)) / nlist.skin
            pairs = cKDTree(r_pc).query_pairs(1.3 * h, output_type="ndarray")
            relative = np.sqrt(((moved_pc[pairs[:, 0]] - moved_pc[pairs[:, 1]]) ** 2).sum(axis=1)).max()
            rows.append(dict(step=int(opt.nsteps), beyond_half_skin=int((moved > 0.5).sum()),
                             q999=float(np.quantile(moved, 0.999)), q99=float(np.quantile(moved, 0.99)),
                             largest=float(moved.max()), largest_relative_within_1_3h=float(relative / nlist.skin)))
        return valid

    neighbors.NeighborList._still_valid = observed
    try:
        opt.run(fmax=0.0, steps=steps)
    finally:
        neighbors.NeighborList._still_valid = still_valid
    record = dict(n=len(atoms), steps=int(opt.nsteps), builds=int(calc.nlist.builds), skin_over_h=calc.nlist.skin / h,
                  rebuilds=rows, most_beyond_half_skin=max(r["beyond_half_skin"] for r in rows),
                  fewest_beyond_half_skin=min(r["beyond_half_skin"] for r in rows),
                  version=subprocess.run(["git", "describe", "--always", "--dirty"], capture_output=True, text=True,
                                         cwd=ROOT).stdout.strip(),
                  command="NUMBA_NUM_THREADS=2 python reproductions/speed-fan-1e6/displacements_at_rebuilds.py "
                          f"{n:g} {out or ''}".strip())
    for r in rows:
        print(r)
    if out:
        Path(out).write_text(json.dumps(record, indent=1) + "\n")


if __name__ == "__main__":
    main(float(sys.argv[1]) if len(sys.argv) > 1 else 1e5, sys.argv[2] if len(sys.argv) > 2 else None)
