#!/bin/bash
# Item 5 part (i): M = 100, 500, six 2D targets, 3 seeds, 1000 evaluations, pilot-tuned baselines (35.8 min at load 6-9).
set -e
cd "$(dirname "$0")/../.."   # the repository root
export OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 PYTHONPATH=$PWD
PY="nice -n 10 ${PYTHON:-python}"
# benchmarks/bench_sampling.py with the sampler defaults the results were made with (reproductions/lib/parvi_pinned.py)
BENCH="$PY reproductions/lib/parvi_pinned.py bench_sampling"
# bench_sampling writes results.json; the registry keeps it gzipped, and the means the READMEs quote in means.json
finish() { gzip -9nf "$1/results.json"; $PY reproductions/lib/parvi_means.py "$1"; }
D=reproductions/parvi-full-m100-500/results
$BENCH --targets gaussian correlated ring8 banana donut funnel --sizes 100 500 --repeats 3 --steps 1000 \
    --wall-factor 3 --sph-variants default local+critical --out $D && finish $D
