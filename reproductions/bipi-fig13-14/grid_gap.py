"""The gap between the fluid and the grid walls of the tanks (README, section (a)), before and after the fix.

    python reproductions/bipi-fig13-14/grid_gap.py   # writes results/grid_gap.json beside it

``rule = "strict"``: wall particles only at cell centres with phi > 0 (``add_walls(..., drop=None)``, the rule
of the runs kept as ``*_gridgap*``); ``rule = "fill_drop"``: they also take the centres ``initial_fill``
dropped within dx/8 of the boundary (``add_walls``' default since 2026-12-02). For the wedge tank: the
side gaps (fluid's outer column to the first wall column, above the floor); for both tanks: the wall
counts, so that a run made with the old rule can be told apart (its JSON's ``n_wall``).
"""
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from ase_sphrelax.drivers.bipi_packer import DROP_FRACTION, add_walls, initial_fill  # noqa: E402
from lib import bipi_sph as example  # noqa: E402

here = Path(__file__).resolve().parent
rows = {}
for case, dx in (("wedge", 0.02), ("wedge", 0.01), ("coral", 0.02)):
    boundary, depth = (example.wedge_tank(), example.DEPTH) if case == "wedge" else (example.coral_tank(dx),
                                                                                       example.CORAL_DEPTH)
    fluid = initial_fill(boundary, dx)
    for rule, drop in (("strict", None), ("fill_drop", DROP_FRACTION)):
        both = add_walls(fluid, boundary, dx, h=example.H_OVER_DX * dx, keep=lambda r: r[:, 1] < depth, drop=drop)
        t, r = both.arrays["type"], both.positions
        row = dict(n_fluid=int((t == 1).sum()), n_wall=int((t == 2).sum()))
        if case == "wedge":
            up = r[:, 1] > 0.05  # above the floor
            right, left = up & (r[:, 0] > 1.5), up & (r[:, 0] < 0.5)
            row.update(fluid_x_max=float(r[(t == 1) & right, 0].max()), right_wall_x_min=float(r[(t == 2) & right, 0].min()),
                       fluid_x_min=float(r[(t == 1) & left, 0].min()), left_wall_x_max=float(r[(t == 2) & left, 0].max()),
                       width=example.WIDTH)
            row["right_gap_dx"] = (row["right_wall_x_min"] - row["fluid_x_max"]) / dx
            row["left_gap_dx"] = (row["fluid_x_min"] - row["left_wall_x_max"]) / dx
        rows[f"{case} dx={dx:g} {rule}"] = row
(here / "results" / "grid_gap.json").write_text(json.dumps(rows, indent=1))
print(json.dumps(rows, indent=1))
