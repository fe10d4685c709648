#!/bin/bash
# part 1: resolution control (fewer neighbours), the i.i.d. start, M = 2000 banana, seeds 1-2; one run at a time
D=examples/results/parvi/rest_vs_time
PY="nice -n 10 /work/main/.venv/bin/python"
export OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 PYTHONPATH=$PWD
while pgrep -f "run_rest.py --targets funnel banana --m 500 --seeds 0 --variants critical" > /dev/null; do sleep 5; done
CP="250 500 1000 2000 4000 8000 16000"
uptime; $PY $D/run_rest.py --targets funnel banana --m 500 --seeds 0 --start iid --checkpoints 0 $CP --out $D/iid_start_m500.json
uptime; $PY $D/run_rest.py --targets funnel banana --m 500 --seeds 0 --n-neighbours 12 --checkpoints $CP --out $D/neighbours_m500.json
uptime; $PY $D/run_rest.py --targets banana --m 2000 --seeds 0 --checkpoints 500 1000 2000 4000 8000 --out $D/banana_m2000.json
uptime; $PY $D/run_rest.py --targets funnel banana --m 500 --seeds 0 --n-neighbours 6 --checkpoints $CP --out $D/neighbours_m500.json
for t in funnel banana; do
  uptime; $PY $D/run_rest.py --targets $t --m 500 --seeds 1 2 --checkpoints 250 500 1000 2000 4000 8000 --out $D/${t}_m500.json
done
uptime
