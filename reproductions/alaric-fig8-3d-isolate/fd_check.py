"""Forces against central differences of the energy on a stored Fig. 8 state (3D, Eq. 46, Delta = 0.01, mirror
ghosts): at the particle with the smallest NN distance, a first-layer particle (r > 0.99) and an interior one
(r < 0.5), each axis, steps 1e-5 and 1e-6. Prints one JSON line per (particle, axis).

    python reproductions/alaric-fig8-3d-isolate/fd_check.py reproductions/alaric-fig8/results/3d_n26411 [--smooth-wall L]

With ``--smooth-wall L`` the calculator is ``alaric_fig8_isolate.smooth_wall_calculator(L)``, and the particle
farthest out (r > 1 when any is outside the ball) replaces the interior one.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
from ase.io import read
from scipy.spatial import cKDTree

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from lib.alaric_fig8_isolate import smooth_wall_calculator  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder")
    ap.add_argument("--smooth-wall", type=float, default=None, metavar="L")
    args = ap.parse_args()
    from ase_sphrelax.calculators.alaric import ALARICCalculator
    from ase_sphrelax.domains import Sphere
    from ase_sphrelax.models.alaric import eq46

    atoms = read(Path(args.folder) / "relaxed.extxyz")
    atoms.set_cell(np.zeros((3, 3)))
    atoms.pbc = False
    atoms.set_momenta(np.zeros((len(atoms), 3)))
    x_pc = atoms.positions
    dist, _ = cKDTree(x_pc).query(x_pc, k=2)
    nn_p = dist[:, 1]
    r_p = np.linalg.norm(x_pc, axis=1)
    last = int(np.argmax(r_p)) if args.smooth_wall is not None else int(np.nonzero(r_p < 0.5)[0][0])
    picks = [int(np.argmin(nn_p)), int(np.nonzero(r_p > 0.99)[0][0]), last]
    density, gradient = eq46(0.01)
    kwargs = dict(target_density=density, target_gradient=gradient, dim=3, form="log",
                  domain=Sphere((0.0, 0.0, 0.0), 1.0), origin=np.zeros(3), boundary="mirror")
    if args.smooth_wall is None:
        calc = ALARICCalculator(**kwargs)
    else:
        calc = smooth_wall_calculator(args.smooth_wall, **kwargs)
    atoms.calc = calc
    f_pc = atoms.get_forces().copy()
    for p in picks:
        for c in range(3):
            fd = {}
            for step in (1e-5, 1e-6):
                e = []
                for sign in (1, -1):
                    moved = atoms.positions.copy()
                    moved[p, c] += sign * step
                    atoms.set_positions(moved)
                    e.append(atoms.get_potential_energy())
                    moved[p, c] -= sign * step
                    atoms.set_positions(moved)
                fd[step] = -(e[0] - e[1]) / (2 * step)
            print(json.dumps(dict(particle=p, r=float(r_p[p]), nn_over_mean=float(nn_p[p] / nn_p.mean()), axis=c,
                                  force=float(f_pc[p, c]), fd_1e5=fd[1e-5], fd_1e6=fd[1e-6])), flush=True)


if __name__ == "__main__":
    main()
