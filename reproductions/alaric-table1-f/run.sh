#!/bin/sh
# Table 1's F run isolated (README.md): one ingredient at a time from Table 1's start, then each variant from five
# starts moved by 1e-6 of the spacing. Run from the repository root (about 30 CPU-minutes in all; the per-step
# isolate/*.csv.gz are regenerated here, not committed). The F_pkg3845804 row needs the package at 3845804 (README.md).
D=reproductions/alaric-table1-f/results
PY="env OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 nice -n 10 python reproductions/alaric-table1-f/run.py"
for v in F F_floor F_C0.1 F_C0.05 S+F V+F; do $PY --variant $v --out $D/isolate; done
$PY --variant F_C0.05 --steps 80000 --name F_C0.05_80000 --out $D/isolate
$PY --variant F_C0.1 --steps 40000 --name F_C0.1_40000 --out $D/isolate
for vc in F:10000 F_floor:10000 S+F:10000 V+F:10000 F_C0.1:30000 F_C0.05:40000; do
  v=${vc%%:*}; cap=${vc##*:}
  for s in 1 2 3 4 5; do
    $PY --variant $v --steps $cap --perturb 1e-6 --seed $s --no-csv --name ${v}_p1e-6_s$s --out $D/perturbed
  done
done
python reproductions/alaric-table1-f/run.py --summarize $D/perturbed
