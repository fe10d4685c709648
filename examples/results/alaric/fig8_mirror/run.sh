#!/bin/sh
# Fig. 8 in 2D with the CLI's defaults (mirror ghosts at the unit disc, log potential): Eq. 46 with Delta = 0.01,
# N = 3772 (the paper's 77 * 7^2 = 3773 rounded to a multiple of 4: 943 particles split once). Run from the
# repository root.
sphrelax density --profile eq46 --delta 0.01 --dim 2 --n 3772 --split 1 --max-steps 10000 \
  --out examples/results/alaric/fig8_mirror/2d --overwrite > examples/results/alaric/fig8_mirror/2d.log 2>&1
# 3D at a reduced N (77 * 3^3 = 2079 rounded to a multiple of 5: 415 particles split once), not the paper's
# 77 * 7^3 = 26 411 (not run: several seconds per step at the load of 2026-12-02).
sphrelax density --profile eq46 --delta 0.01 --dim 3 --n 2075 --split 1 --max-steps 3000 \
  --out examples/results/alaric/fig8_mirror/3d_n2075 --overwrite > examples/results/alaric/fig8_mirror/3d_n2075.log 2>&1
