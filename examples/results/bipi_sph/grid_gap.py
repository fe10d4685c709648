"""The 2 dx gap of the wedge tank's grid walls at the right wall (README, section (a)).

    python examples/results/bipi_sph/grid_gap.py   # writes grid_gap.json beside it
"""
import importlib.util
import json
from pathlib import Path

import numpy as np

from ase_sphrelax.drivers.bipi_packer import initial_fill

here = Path(__file__).resolve().parent
spec = importlib.util.spec_from_file_location("bipi_sph", here.parents[1] / "bipi_sph.py")
example = importlib.util.module_from_spec(spec)
spec.loader.exec_module(example)
rows = {}
for dx in (0.02, 0.01):
    boundary = example.wedge_tank()
    both = example.with_walls(initial_fill(boundary, dx), boundary, dx, example.H_OVER_DX * dx, example.DEPTH)
    t, r = both.arrays["type"], both.positions
    side = (r[:, 1] > 0.05) & (r[:, 0] > 1.5)  # above the floor, right half
    rows[f"dx={dx:g}"] = dict(fluid_x_max=float(r[(t == 1) & side, 0].max()),
                              right_wall_x_min=float(r[(t == 2) & side, 0].min()),
                              left_wall_x_max=float(r[(t == 2) & (r[:, 1] > 0.05) & (r[:, 0] < 0.5), 0].max()),
                              fluid_x_min=float(r[t == 1, 0].min()), width=example.WIDTH)
    rows[f"dx={dx:g}"]["right_gap_dx"] = (rows[f"dx={dx:g}"]["right_wall_x_min"] - rows[f"dx={dx:g}"]["fluid_x_max"]) / dx
    rows[f"dx={dx:g}"]["left_gap_dx"] = (rows[f"dx={dx:g}"]["fluid_x_min"] - rows[f"dx={dx:g}"]["left_wall_x_max"]) / dx
(here / "grid_gap.json").write_text(json.dumps(rows, indent=1))
print(json.dumps(rows, indent=1))
