#!/bin/bash
# Item 5 completion (run 2026-12-02 12:22-13:31 UTC, git b4d306e): SVGD M=2000 seeds 1-2 on four 2D targets, then the
# logistic posterior at M=2000 (3 seeds). Run then with the sampler defaults of that day, pinned here by
# reproductions/lib/parvi_pinned.py (the run called benchmarks/bench_sampling.py directly); the times.txt/log.txt
# files it wrote are not kept.
cd "$(dirname "$0")/../.."   # the repository root
export OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 PYTHONPATH=$PWD
PY=${PYTHON:-python}
BENCH="reproductions/lib/parvi_pinned.py bench_sampling"
for SEED in 1 2; do for T in gaussian correlated donut funnel; do
  O=reproductions/parvi-full-m2000/results/svgd_seeds12/${T}_seed$SEED; mkdir -p $O
  nice -n 10 $PY $BENCH --targets $T --sizes 2000 --repeats 1 --repeats-large 1 \
     --first-seed $SEED --steps 1000 --sph-variants --baselines svgd --out $O > $O/log.txt 2>&1
  gzip -9nf $O/results.json
done; done
for SEED in 0 1 2; do
  O=reproductions/parvi-full-highdim/results/m2000_logistic_seed$SEED; mkdir -p $O
  nice -n 10 $PY $BENCH --targets logistic --sizes 2000 --repeats 1 --repeats-large 1 \
     --first-seed $SEED --steps 1000 --sph-variants default knn+whiten --wall-factor 3 --out $O > $O/log.txt 2>&1
  gzip -9nf $O/results.json
done
echo ALLDONE
