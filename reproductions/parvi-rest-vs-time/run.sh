#!/bin/bash
# Every run of this entry, in the order it was made (from the repository root; one at a time; ~10 CPU-hours).
# (The queue logs of the original runs are not kept; a few queued runs were cancelled and are not in any JSON.)
# Rows carry their git rev and load. The scripts pin the sampler defaults the results were made with
# (reproductions/lib/parvi_pinned.py). snapshots/ (particle positions, 3.6 MB) are made by run_rest.py, not kept;
# snapshot_energy.py and line_law.py read them.
set -e
D=reproductions/parvi-rest-vs-time/results
S=reproductions/parvi-rest-vs-time
PY="nice -n 10 ${PYTHON:-python}"
export OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 PYTHONPATH=$PWD
CP="250 500 1000 2000 4000 8000 16000"
# 1. K = 1 (local+critical) against steps, seed 0
$PY $S/run_rest.py --targets funnel --m 500 --seeds 0 --checkpoints $CP --out $D/funnel_m500.json.gz
$PY $S/run_rest.py --targets banana --m 500 --seeds 0 --checkpoints $CP --out $D/banana_m500.json.gz
$PY $S/run_rest.py --targets funnel --m 2000 --seeds 0 --checkpoints 500 1000 2000 4000 8000 --out $D/funnel_m2000.json
# controls at M = 500, seed 0: local steps with a growth cap; global steps (critical friction, the default); the
# i.i.d. start; 12 neighbours; a per-particle drag along the score
$PY $S/run_rest.py --targets funnel --m 500 --seeds 0 --local-growth 1.05 --checkpoints $CP --out $D/control_m500.json.gz
$PY $S/run_rest.py --targets funnel banana --m 500 --seeds 0 --variants critical default --checkpoints $CP 32000 \
    --out $D/control_m500.json.gz
$PY $S/run_rest.py --targets funnel banana --m 500 --seeds 0 --start iid --checkpoints 0 $CP --out $D/iid_start_m500.json.gz
$PY $S/run_rest.py --targets funnel banana --m 500 --seeds 0 --n-neighbours 12 --checkpoints $CP --out $D/neighbours_m500.json
$PY $S/run_rest.py --targets banana --m 2000 --seeds 0 --checkpoints 500 1000 2000 4000 8000 --out $D/banana_m2000.json
$PY $S/run_rest.py --targets funnel banana --m 500 --seeds 0 --particle-drag --checkpoints $CP --out $D/particle_drag_m500.json
# 2. fewer neighbours per support, with and without the per-particle hold, 1000 evaluations (run_sph.py), seed 0
for m in 500 2000; do
  $PY reproductions/lib/parvi_run_sph.py --targets funnel banana --m $m --steps 1000 --seeds 0 --variants local+critical+n_neighbours=12 \
      local+critical+score_every=adaptive+n_neighbours=12 --out $D/remedy_m$m.json
done
for m in 500 2000; do
  $PY reproductions/lib/parvi_run_sph.py --targets funnel banana --m $m --steps 1000 --seeds 0 \
      --variants local+critical+score_every=adaptive+n_neighbours=20 local+critical+score_every=adaptive+n_neighbours=16 \
      --out $D/remedy_m$m.json
done
# 3. 12 neighbours with longer holds
$PY reproductions/lib/parvi_run_sph.py --targets banana --m 2000 --steps 1000 --seeds 0 \
    --variants local+critical+score_every=adaptive+n_neighbours=12+hold_max=8 --out $D/remedy_m2000.json
$PY reproductions/lib/parvi_run_sph.py --targets funnel banana --m 500 --steps 1000 --seeds 0 \
    --variants local+critical+score_every=adaptive+n_neighbours=12+hold_max=8 --out $D/remedy_m500.json
$PY reproductions/lib/parvi_run_sph.py --targets funnel --m 2000 --steps 1000 --seeds 0 \
    --variants local+critical+score_every=adaptive+n_neighbours=12+hold_max=8 --out $D/remedy_m2000.json
V=local+critical+score_every=adaptive+n_neighbours=12+hold_max=6
$PY reproductions/lib/parvi_run_sph.py --targets funnel banana --m 500 --steps 1000 --seeds 0 --variants $V --out $D/remedy_m500.json
$PY reproductions/lib/parvi_run_sph.py --targets banana funnel --m 2000 --steps 1000 --seeds 0 --variants $V --out $D/remedy_m2000.json
# the model energy of the checkpoints
$PY $S/snapshot_energy.py $D/snapshots/funnel_m500_s0_local_critical.npz $D/snapshots/funnel_m500_s0_local_critical_growth1.05.npz \
    $D/snapshots/banana_m500_s0_local_critical.npz $D/snapshots/funnel_m2000_s0_local_critical.npz --out $D/snapshot_energy.json
$PY $S/snapshot_energy.py $D/snapshots/funnel_m500_s0_default.npz $D/snapshots/funnel_m500_s0_critical.npz --out $D/snapshot_energy.json
$PY $S/snapshot_energy.py $D/snapshots/funnel_m500_s0_local_critical_startiid.npz $D/snapshots/banana_m500_s0_default.npz \
    $D/snapshots/banana_m500_s0_critical.npz --out $D/snapshot_energy.json
$PY $S/snapshot_energy.py $D/snapshots/funnel_m500_s0_local_critical_pdrag.npz --out $D/snapshot_energy.json
$PY $S/summarize.py   # summary.md
# 1 (seeds 1 and 2 at M = 500)
for t in funnel banana; do
  $PY $S/run_rest.py --targets $t --m 500 --seeds 1 2 --checkpoints 250 500 1000 2000 4000 8000 --out $D/${t}_m500.json.gz
done
# 3. the one configuration, six 2D targets, seeds 0-2, M = 500 and 2000 (1000 evaluations per particle)
V=local+critical+score_every=adaptive+n_neighbours=12+hold_max=scaled
for m in 500 2000; do
  $PY reproductions/lib/parvi_run_sph.py --targets funnel banana gaussian correlated ring8 donut --m $m --steps 1000 --seeds 0 1 2 \
      --variants $V --out $D/one_config_m$m.json
done
$PY $S/line_law.py   # line_law.json
# 4. the one configuration with 2000 and 4000 evaluations (is the funnel's number a transient?)
$PY reproductions/lib/parvi_run_sph.py --targets funnel banana --m 500 --steps 2000 4000 --seeds 0 --variants $V --out $D/one_config_budget.json
