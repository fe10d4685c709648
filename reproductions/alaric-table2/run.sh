#!/bin/sh
# Table 2, ALARIC's dynamics alone (the command): eps_stag per Delta, 101 particles split once to 303.
# Run from the repository root: sh reproductions/alaric-table2/run.sh
for d in 0 0.01 0.05 0.1 0.5 1; do
  sphrelax density --profile eq46 --delta $d --dim 1 --n 303 --split 1 --no-polish --form log \
    --out reproductions/alaric-table2/results/delta_$d > reproductions/alaric-table2/results/delta_$d.log 2>&1
done
# the integral error and the bottom of the well per run (integral.md, integral.json)
python reproductions/lib/alaric_table2_summary.py reproductions/alaric-table2/results
# the limiting ingredient isolated (isolate.md, isolate.json, isolate/delta_D/)
python reproductions/lib/alaric_reproduce.py --only b2 --deltas 0,0.01,0.05,0.1,0.5,1 --out reproductions/alaric-table2/results
# the dynamics followed by the least-squares polish (2026-12-01, Omega floored; polish/table2.md)
python reproductions/lib/alaric_reproduce.py --only b --out reproductions/alaric-table2/results/polish
