#!/bin/bash
# Item 5 at M = 2000, 1000 evaluations: part 1 (banana, funnel; 11.6 min), part 2 (the other four 2D targets; 20.8 min),
# SVGD seed 0 (49 min), SVGD seeds 1-2 (banana and ring here; the other four targets: run_item5_completion.sh).
set -e
cd "$(dirname "$0")/../.."   # the repository root
export OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 PYTHONPATH=$PWD
PY="nice -n 10 ${PYTHON:-python}"
# benchmarks/bench_sampling.py with the sampler defaults the results were made with (reproductions/lib/parvi_pinned.py)
BENCH="$PY reproductions/lib/parvi_pinned.py bench_sampling"
# bench_sampling writes results.json; the registry keeps it gzipped, and the means the READMEs quote in means.json
finish() { gzip -9nf "$1/results.json"; $PY reproductions/lib/parvi_means.py "$1"; }
D=reproductions/parvi-full-m2000/results
$BENCH --targets banana funnel --sizes 2000 --repeats 3 --repeats-large 3 --steps 1000 --wall-factor 3 \
    --sph-variants default local+critical --baselines ula mala emcee --out $D/part1 && finish $D/part1
$BENCH --targets gaussian correlated ring8 donut --sizes 2000 --repeats 3 --repeats-large 3 --steps 1000 --wall-factor 3 \
    --sph-variants default local+critical --baselines ula mala emcee --out $D/part2 && finish $D/part2
$BENCH --targets gaussian correlated ring8 banana donut funnel --sizes 2000 --repeats 1 --repeats-large 1 --first-seed 0 \
    --steps 1000 --sph-variants --baselines svgd --out $D/svgd && finish $D/svgd
for SEED in 1 2; do for T in banana ring8; do
  O=$D/svgd_seeds12/${T}_seed$SEED
  $BENCH --targets $T --sizes 2000 --repeats 1 --repeats-large 1 --first-seed $SEED --steps 1000 --sph-variants \
      --baselines svgd --out $O && gzip -9nf $O/results.json
done; done
