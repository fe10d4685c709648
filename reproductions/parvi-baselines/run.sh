#!/bin/bash
# The first evaluation (item 5; 400 evaluations per particle, hand-set baselines then: --tuning table --sph-friction 1
# reproduces them; see README.md). quick: ~30 min, m2000: ~1 h, m2000_highdim: ~10 min, m100_500_full: ~13 min.
set -e
cd "$(dirname "$0")/../.."   # the repository root
export OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 PYTHONPATH=$PWD
PY="nice -n 10 ${PYTHON:-python}"
# benchmarks/bench_sampling.py with the sampler defaults the results were made with (reproductions/lib/parvi_pinned.py)
BENCH="$PY reproductions/lib/parvi_pinned.py bench_sampling"
# bench_sampling writes results.json; the registry keeps it gzipped, and the means the READMEs quote in means.json
finish() { gzip -9nf "$1/results.json"; $PY reproductions/lib/parvi_means.py "$1"; }
D=reproductions/parvi-baselines/results
$BENCH --quick --tuning table --sph-friction 1 --out $D/quick && finish $D/quick
$BENCH --quick --repeats 3 --tuning table --sph-friction 1 --out $D/quick_r3 && finish $D/quick_r3
$BENCH --sizes 2000 --repeats 2 --steps 400 --wall-factor 3 --tuning table --sph-friction 1 --out $D/m2000 && finish $D/m2000
$BENCH --targets gaussian10d logistic --sizes 2000 --steps 400 --wall-factor 3 --tuning table --sph-friction 1 \
    --out $D/m2000_highdim && finish $D/m2000_highdim
$BENCH --sizes 100 500 --repeats 3 --steps 1000 --tuning table --sph-friction 1 --out $D/m100_500_full && finish $D/m100_500_full
