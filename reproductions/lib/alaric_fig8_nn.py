"""Fig. 8's checks beside epsilon, from a `sphrelax density` output folder: pairing (smallest nearest-neighbour
distance over the mean) and the bottom of the well (the particle closest to the centre, particles within r < 0.15).

    python reproductions/lib/alaric_fig8_nn.py reproductions/alaric-fig8/results/3d_n26411 [--json FILE --key NAME]

Prints one JSON object; with ``--json`` it is also stored under ``--key`` in FILE (other keys kept).
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from ase.io import read
from scipy.spatial import cKDTree


def layer_checks(x_pd, radius=1.0, layers=2.0):
    """Pairing by layer: the smallest nearest-neighbour distance over the mean (the mean over all particles) in
    the edge layer (``radius - r`` below ``layers`` mean nearest-neighbour distances) and in the interior, the
    particles below 0.5 of the mean in each, the closest particle to r = 0 and the particles within r < 0.15."""
    dist, _ = cKDTree(x_pd).query(x_pd, k=2)
    nn_p = dist[:, 1]
    mean = float(nn_p.mean())
    r_p = np.linalg.norm(x_pd, axis=1)
    edge_p = radius - r_p < layers * mean
    row = dict(nn_mean=mean, nn_min_over_mean=float(nn_p.min() / mean))
    for name, m in (("edge", edge_p), ("interior", ~edge_p)):
        row[f"{name}_n"] = int(m.sum())
        row[f"{name}_nn_min_over_mean"] = float(nn_p[m].min() / mean) if m.any() else None
        row[f"{name}_below_half"] = int(np.count_nonzero(nn_p[m] < 0.5 * mean))
    paired_r = r_p[nn_p < 0.5 * mean]
    row["paired_r_range"] = [float(paired_r.min()), float(paired_r.max())] if len(paired_r) else None
    row.update(r_min=float(r_p.min()), particles_within_0_15=int(np.count_nonzero(r_p < 0.15)))
    return row


def fig8_checks(folder):
    folder = Path(folder)
    summary = json.loads((folder / "summary.json").read_text())
    dim = int(summary["dim"])
    x = read(folder / "relaxed.extxyz").positions[:, :dim]  # in the target's frame (centre at 0)
    dist, _ = cKDTree(x).query(x, k=2)
    r = np.linalg.norm(x, axis=1)
    return dict(epsilon=summary["epsilon"], epsilon_teo_min=summary["epsilon_teo_min"], steps=summary["steps"],
                stop=summary["stop_reason"], converged=summary["converged"], boundary=summary["boundary"],
                n=len(x), nn_min_over_mean=float(dist[:, 1].min() / dist[:, 1].mean()), r_min=float(r.min()),
                particles_within_0_15=int(np.count_nonzero(r < 0.15)), wall_time_s=summary["wall_time_s"],
                layers=layer_checks(x) if dim == 3 else None)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder")
    ap.add_argument("--json", default=None)
    ap.add_argument("--key", default=None)
    args = ap.parse_args()
    row = fig8_checks(args.folder)
    print(json.dumps(row, indent=1))
    if args.json:
        path = Path(args.json)
        table = json.loads(path.read_text()) if path.exists() else {}
        table[args.key or Path(args.folder).name] = row
        path.write_text(json.dumps(table, indent=1))


if __name__ == "__main__":
    main()
