#!/bin/sh
# Fig. 8 in 1D (issue 20 item 2): Eq. 46 with Delta = 0.01 on the periodic [-1, 1), N = 537 (the paper's 77 * 7 = 539
# rounded to a multiple of 3: 179 particles split once), the CLI's defaults (log potential; in 1D the least-squares
# polish is on by default), and the same with --no-polish (the dynamics alone). Run from the repository root.
sphrelax density --profile eq46 --delta 0.01 --dim 1 --n 537 --split 1 --form log \
  --out reproductions/alaric-fig8-1d/results/default --overwrite > reproductions/alaric-fig8-1d/results/default.log 2>&1
sphrelax density --profile eq46 --delta 0.01 --dim 1 --n 537 --split 1 --no-polish --form log \
  --out reproductions/alaric-fig8-1d/results/no_polish --overwrite > reproductions/alaric-fig8-1d/results/no_polish.log 2>&1
python reproductions/lib/alaric_table2_summary.py reproductions/alaric-fig8-1d/results
