#!/bin/sh
# Table 2, ALARIC's dynamics alone with --finish squares (the log potential, then the least-squares
# potential from where it stopped; the command plus --finish squares): eps_stag per Delta.
# Run from the repository root: sh reproductions/alaric-table2-two-stage/run.sh
for d in 0 0.01 0.05 0.1 0.5 1; do
  sphrelax density --profile eq46 --delta $d --dim 1 --n 303 --split 1 --no-polish --finish squares --form log --overwrite \
    --out reproductions/alaric-table2-two-stage/results/delta_$d > reproductions/alaric-table2-two-stage/results/delta_$d.log 2>&1
done
# the integral error and the bottom of the well per run (integral.md, integral.json)
python reproductions/lib/alaric_table2_summary.py reproductions/alaric-table2-two-stage/results
