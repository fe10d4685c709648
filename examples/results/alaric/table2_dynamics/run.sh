#!/bin/sh
# Table 2, ALARIC's dynamics alone (the command): eps_stag per Delta, 101 particles split once to 303.
# Run from the repository root: sh examples/results/alaric/table2_dynamics/run.sh
for d in 0 0.01 0.05 0.1 0.5 1; do
  sphrelax density --profile eq46 --delta $d --dim 1 --n 303 --split 1 --no-polish \
    --out examples/results/alaric/table2_dynamics/delta_$d > examples/results/alaric/table2_dynamics/delta_$d.log 2>&1
done
