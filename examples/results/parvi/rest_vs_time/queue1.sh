#!/bin/bash
# part 1 of the experiment, one run at a time (from the worktree root)
set -e
D=examples/results/parvi/rest_vs_time
PY="nice -n 10 /work/main/.venv/bin/python"
export OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 PYTHONPATH=$PWD
for t in funnel banana; do
  uptime
  $PY $D/run_rest.py --targets $t --m 500 --seeds 0 --checkpoints 250 500 1000 2000 4000 8000 16000 --out $D/${t}_m500.json
done
for t in funnel banana; do
  uptime
  $PY $D/run_rest.py --targets $t --m 2000 --seeds 0 --checkpoints 500 1000 2000 4000 8000 --out $D/${t}_m2000.json
done
for t in funnel banana; do
  uptime
  $PY $D/run_rest.py --targets $t --m 500 --seeds 1 2 --checkpoints 250 500 1000 2000 4000 8000 --out $D/${t}_m500.json
done
uptime
