#!/bin/sh
# Table 2, ALARIC's dynamics alone with --finish squares (the log potential, then the least-squares
# potential from where it stopped; the command plus --finish squares): eps_stag per Delta.
# Run from the repository root: sh examples/results/alaric/table2_two_stage/run.sh
for d in 0 0.01 0.05 0.1 0.5 1; do
  sphrelax density --profile eq46 --delta $d --dim 1 --n 303 --split 1 --no-polish --finish squares --overwrite \
    --out examples/results/alaric/table2_two_stage/delta_$d > examples/results/alaric/table2_two_stage/delta_$d.log 2>&1
done
