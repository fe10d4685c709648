"""Seam check and tiled figure of the periodic packing in results/run/ (written by ``run.sh``).

Nearest-neighbour distances by minimum image (a k-d tree over the particles and their images x -+ L):
the particles within 1 dx of the periodic faces x = 0 and x = L against the others, both away from the walls
(beyond 2 dx of every wall); writes results/seam.json and results/tiled.png (three periods side by side, the seam dashed).
"""
import gzip
import json
from pathlib import Path

import matplotlib
import numpy as np
from ase.io import read
from scipy.spatial import cKDTree

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

here = Path(__file__).resolve().parent / "results"
atoms = read(here / "run" / "packed.extxyz")
with gzip.open(here / "run" / "summary.json.gz", "rt") as fh:  # run.sh gzips the CLI's summary.json
    summary = json.load(fh)["summary"]
dx, L = summary["dx"], float(atoms.cell[0, 0])
x, y = atoms.positions[:, 0], atoms.positions[:, 1]
r = atoms.positions[:, :2]
images = np.concatenate([r + [k * L, 0.0] for k in (-1, 0, 1)])
nearest = cKDTree(images).query(r, k=2)[0][:, 1]  # k=1 is the particle itself
away = (y > 2 * dx) & (y < 0.1 - 2 * dx) & (np.hypot(x - 0.05, y - 0.05) > 0.02 + 2 * dx)
seam = away & ((x < dx) | (x > L - dx))
bulk = away & ~((x < dx) | (x > L - dx))
out = dict(dx=dx, period=L, n_particles=len(atoms), pbc=[bool(p) for p in atoms.pbc],
           x_min=float(x.min()), x_max=float(x.max()), n_seam=int(seam.sum()), n_bulk=int(bulk.sum()),
           nearest_seam_median_dx=float(np.median(nearest[seam]) / dx),
           nearest_seam_min_dx=float(nearest[seam].min() / dx),
           nearest_bulk_median_dx=float(np.median(nearest[bulk]) / dx),
           nearest_bulk_min_dx=float(nearest[bulk].min() / dx))
(here / "seam.json").write_text(json.dumps(out, indent=1) + "\n")
print(json.dumps(out, indent=1))

fig, ax = plt.subplots(figsize=(9, 3.4))
for k in range(3):
    ax.scatter(x + k * L, y, s=2.5, c="C0" if k == 1 else "0.55", lw=0)
    ax.add_patch(plt.Circle((0.05 + k * L, 0.05), 0.02, fill=False, lw=0.8))
    ax.axvline(k * L, ls="--", lw=0.6, c="C3")
ax.axvline(3 * L, ls="--", lw=0.6, c="C3")
ax.axhline(0, c="k", lw=0.8)
ax.axhline(0.1, c="k", lw=0.8)
ax.set_aspect("equal")
ax.set_title(f"periodic in x: {len(atoms)} particles per period (blue), its images (grey); seams dashed")
fig.tight_layout()
fig.savefig(here / "tiled.png", dpi=150)
