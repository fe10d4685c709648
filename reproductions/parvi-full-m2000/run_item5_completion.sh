#!/bin/bash
# Item 5 completion (run 2026-12-02 12:22-13:31 UTC, git b4d306e): SVGD M=2000 seeds 1-2 on four 2D targets, then the logistic posterior at M=2000 (3 seeds).
cd "$(dirname "$0")/../../.."   # the repository root
export OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 PYTHONPATH=.
PY=${PY:-.venv/bin/python}   # the run used the main checkout's venv
R=examples/results/parvi
for SEED in 1 2; do for T in gaussian correlated donut funnel; do
  O=$R/full_m2000_svgd_seeds12/${T}_seed$SEED; mkdir -p $O
  echo "start $(date -u +%H:%M:%S) $(cut -d' ' -f1-3 /proc/loadavg)" > $O/times.txt
  nice -n 10 $PY benchmarks/bench_sampling.py --targets $T --sizes 2000 --repeats 1 --repeats-large 1 \
     --first-seed $SEED --steps 1000 --sph-variants --baselines svgd --out $O > $O/log.txt 2>&1
  echo "end $(date -u +%H:%M:%S) $(cut -d' ' -f1-3 /proc/loadavg) rc=$?" >> $O/times.txt
done; done
for SEED in 0 1 2; do
  O=$R/full_highdim/m2000_logistic_seed$SEED; mkdir -p $O
  echo "start $(date -u +%H:%M:%S) $(cut -d' ' -f1-3 /proc/loadavg)" > $O/times.txt
  nice -n 10 $PY benchmarks/bench_sampling.py --targets logistic --sizes 2000 --repeats 1 --repeats-large 1 \
     --first-seed $SEED --steps 1000 --sph-variants default knn+whiten --wall-factor 3 --out $O > $O/log.txt 2>&1
  echo "end $(date -u +%H:%M:%S) $(cut -d' ' -f1-3 /proc/loadavg) rc=$?" >> $O/times.txt
done
echo ALLDONE
