#!/bin/bash
# part 1 controls and the rest of queue1, one run at a time (from the worktree root)
D=examples/results/parvi/rest_vs_time
PY="nice -n 10 /work/main/.venv/bin/python"
export OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 PYTHONPATH=$PWD
while pgrep -f "run_rest.py --targets funnel --m 2000" > /dev/null; do sleep 5; done
CP="250 500 1000 2000 4000 8000 16000"
uptime; $PY $D/run_rest.py --targets funnel --m 500 --seeds 0 --variants local+critical --local-growth 1.05 --checkpoints $CP --out $D/control_m500.json
uptime; $PY $D/run_rest.py --targets funnel banana --m 500 --seeds 0 --variants critical default --checkpoints $CP 32000 --out $D/control_m500.json
uptime; $PY $D/run_rest.py --targets banana --m 500 --seeds 0 --variants local+critical --local-growth 1.05 --checkpoints $CP --out $D/control_m500.json
uptime; $PY $D/run_rest.py --targets banana --m 2000 --seeds 0 --checkpoints 500 1000 2000 4000 8000 --out $D/banana_m2000.json
for t in funnel banana; do
  uptime; $PY $D/run_rest.py --targets $t --m 500 --seeds 1 2 --checkpoints 250 500 1000 2000 4000 8000 --out $D/${t}_m500.json
done
uptime
