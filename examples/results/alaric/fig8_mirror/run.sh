#!/bin/sh
# Fig. 8 in 2D with the CLI's defaults (mirror ghosts at the unit disc, log potential): Eq. 46 with Delta = 0.01,
# N = 3772 (the paper's 77 * 7^2 = 3773 rounded to a multiple of 4: 943 particles split once). Run from the
# repository root.
sphrelax density --profile eq46 --delta 0.01 --dim 2 --n 3772 --split 1 --max-steps 10000 \
  --out examples/results/alaric/fig8_mirror/2d --overwrite > examples/results/alaric/fig8_mirror/2d.log 2>&1
