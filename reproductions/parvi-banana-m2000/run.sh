#!/bin/bash
# Every run of this entry (README.md names each row's git revision; ~4 h in all). The runner pins the sampler
# defaults the results were made with (reproductions/lib/parvi_pinned.py).
set -e
cd "$(dirname "$0")/../.."   # the repository root
export OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 PYTHONPATH=$PWD
PY="nice -n 10 ${PYTHON:-python}"
S=reproductions/parvi-banana-m2000
D=$S/results
# 1. more steps
$PY $S/run.py --targets banana --steps 1000 2000 --seeds 1 0 2 --variants local+critical --out $D/steps.json
$PY $S/run.py --targets banana --steps 4000 --seeds 1 --variants local+critical --out $D/steps.json
# 2. coarse to fine, and the two levels by hand
$PY $S/run.py --targets banana funnel --steps 1000 --seeds 1 0 2 --variants local+critical+coarse coarse --out $D/coarse.json
$PY $S/diagnose_coarse.py --targets banana funnel --seeds 1
# 3. the score held over 4 steps
$PY $S/run.py --targets banana --steps 1000 --seeds 1 0 2 --variants local+critical+score_every=4 --out $D/score_every.json
$PY $S/run.py --targets funnel --steps 1000 --seeds 1 0 2 --variants local+critical+score_every=4 --out $D/score_every.json
$PY $S/run.py --targets ring8 donut correlated gaussian --steps 1000 --seeds 0 1 2 --variants local+critical+score_every=4 \
    --out $D/score_every.json
# 4. SVGD's cost per step; 5. the default's ring with 2000 steps
$PY $S/svgd_cost.py
$PY $S/run.py --targets ring8 --steps 2000 --seeds 0 --variants default --out $D/ring_default.json
$PY $S/summarize.py   # summary.md
