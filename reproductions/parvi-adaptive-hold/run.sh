#!/bin/bash
# Every run of this entry (README.md's commands; ~3 h in all). The runner pins the sampler defaults the results were
# made with (reproductions/lib/parvi_pinned.py).
set -e
cd "$(dirname "$0")/../.."   # the repository root
export OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 PYTHONPATH=$PWD
RUN="nice -n 10 ${PYTHON:-python} reproductions/lib/parvi_run_sph.py"
D=reproductions/parvi-adaptive-hold/results
V=local+critical+score_every=adaptive+hold_tolerance=0.02+hold_max=4
$RUN --targets funnel banana --steps 1000 --seeds 0 --variants local+critical+score_every=adaptive --out $D/adaptive.json
$RUN --targets funnel --steps 4000 --seeds 0 --variants local+critical --out $D/funnel_time.json
$RUN --targets funnel --steps 1000 --seeds 0 --variants local+critical+score_every=adaptive+hold_tolerance=0.02 $V \
    --out $D/tolerance.json
$RUN --targets banana --steps 1000 --seeds 0 --variants $V --out $D/tolerance.json
$RUN --targets funnel banana --steps 1000 --seeds 1 2 --variants $V --out $D/tolerance.json
$RUN --targets gaussian correlated ring8 donut --steps 1000 --seeds 0 --variants $V --out $D/others.json
$RUN --targets funnel --steps 1000 --seeds 0 --variants local+critical+score_every=5 $V --out $D/control.json
$RUN --targets gaussian correlated ring8 donut --steps 1000 --seeds 1 2 --variants $V --out $D/others.json
$RUN --targets banana --steps 1000 --seeds 0 --variants $V --out $D/control.json
$RUN --targets gaussian correlated ring8 banana donut funnel --m 500 --steps 1000 --seeds 0 1 2 \
    --variants local+critical+score_every=adaptive --out $D/m500_adaptive.json
nice -n 10 ${PYTHON:-python} reproductions/parvi-adaptive-hold/summarize.py   # summary.md
