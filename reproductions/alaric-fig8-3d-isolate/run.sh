#!/bin/sh
# Every command behind fig8_3d_isolate/ (issue 20 item 2, Fig. 8 in 3D), in the order they ran on 2026-12-02, from the
# repository root; each niced, one thread. Load averages at each run's start and end: <name>.uptime.
# sphrelax = python -m ase_sphrelax.cli (the venv python; PYTHONPATH is the repository root)
D=reproductions/alaric-fig8-3d-isolate/results
export PYTHONPATH=$PWD
PY="env OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 nice -n 10 python"
run() { name=$1; shift; uptime > $D/$name.uptime; $PY "$@" > $D/$name.log 2>&1; uptime >> $D/$name.uptime; }

# (a) the confounder split 0 / split 1 at N = 2075 (CLI, the recipe of fig8_mirror/3d_n2075_after, same caps)
run a_n2075_split0 -m ase_sphrelax.cli density --profile eq46 --delta 0.01 --dim 3 --n 2075 --split 0 --form log \
  --max-steps 6000 --max-wall 600 --out $D/a_n2075_split0 --overwrite
run a_n2075_split1 -m ase_sphrelax.cli density --profile eq46 --delta 0.01 --dim 3 --n 2075 --split 1 --form log \
  --max-steps 6000 --max-wall 600 --out $D/a_n2075_split1 --overwrite
# (e) split 1 at the paper's size: N = 26 415 = 5283 x 5 (26 411 is not a multiple of 5), tracked every 200 steps;
# started beside the queue at 09:22 and stopped by hand at its split (step 4000, 09:52) once its stage 0 (N = 5283,
# split 0, the same start as d_*) had paired: its nn_trace.json is the N = 5283 baseline of the d_* runs.
run e_n26415_split1 reproductions/lib/alaric_fig8_isolate.py fresh --n 26415 --split 1 --max-steps 8000 --max-wall 5100 \
  --every 200 --out $D/e_n26415_split1
# (b) N = 9625 = 77 x 5^3 with one splitting stage (stage 0: 1925 particles, 1500 steps), tracked
run b_n9625_split1 reproductions/lib/alaric_fig8_isolate.py fresh --n 9625 --split 1 --max-steps 3000 --max-wall 900 \
  --every 100 --out $D/b_n9625_split1
# (d) the edge treatment at N = 5283, split 0: truncated kernels (boundary wall) instead of mirror ghosts
run d_n5283_wall reproductions/lib/alaric_fig8_isolate.py fresh --n 5283 --split 0 --boundary wall --max-steps 800 \
  --max-wall 480 --every 100 --out $D/d_n5283_wall
# the FD force checks (forces against central differences of the energy)
python reproductions/alaric-fig8-3d-isolate/fd_check.py reproductions/alaric-fig8/results/3d_n26411 > $D/fd_check_n26411.jsonl
python reproductions/alaric-fig8-3d-isolate/fd_check.py $D/a_n2075_split1 --smooth-wall 1 > $D/fd_check_n2075_smooth1.jsonl
# is the dynamics dissipative? 300 steps from a_n2075_split1, one ingredient changed at a time
for v in "default:" "cfl01:--cfl 0.1" "wall10:--wall-length-factor 10" "smooth1:--smooth-wall 1" "smooth05:--smooth-wall 0.5" \
    "noviscosity:--no-viscosity"; do
  $PY reproductions/alaric-fig8-3d-isolate/energy_check.py continue $D/a_n2075_split1 --max-steps 300 ${v#*:} --out $D/energy/n2075_${v%%:*}.json
done
# (d) the wall made smooth (quadratic, no force jump at the boundary) at N = 5283, split 0
run d_n5283_smooth1 reproductions/lib/alaric_fig8_isolate.py fresh --n 5283 --split 0 --smooth-wall 1 --max-steps 800 \
  --max-wall 480 --every 100 --out $D/d_n5283_smooth1
run d_n5283_smooth05 reproductions/lib/alaric_fig8_isolate.py fresh --n 5283 --split 0 --smooth-wall 0.5 --max-steps 800 \
  --max-wall 480 --every 100 --out $D/d_n5283_smooth05
# (c) continuations of the stored N = 26 411 state (fig8_mirror/3d_n26411; zero start velocities), in parallel with
# the queue above: the package's linear wall (control) and the smooth wall (L = 1, stopped by hand after 250 steps
# once d_n5283_smooth1 showed that L = 1 lets the outer layer leave the ball; then L = 0.5)
run c_n26411_continue reproductions/lib/alaric_fig8_isolate.py continue reproductions/alaric-fig8/results/3d_n26411 \
  --max-steps 20000 --max-wall 900 --every 50 --out $D/c_n26411_continue
run c_n26411_smooth1 reproductions/lib/alaric_fig8_isolate.py continue reproductions/alaric-fig8/results/3d_n26411 \
  --smooth-wall 1 --max-steps 20000 --max-wall 1800 --every 50 --out $D/c_n26411_smooth1
run c_n26411_smooth05 reproductions/lib/alaric_fig8_isolate.py continue reproductions/alaric-fig8/results/3d_n26411 \
  --smooth-wall 0.5 --max-steps 20000 --max-wall 1500 --every 50 --out $D/c_n26411_smooth05
# a stiffer smooth wall (L = 0.25): the energy check and N = 5283 (after the runs above)
$PY reproductions/alaric-fig8-3d-isolate/energy_check.py continue $D/a_n2075_split1 --max-steps 300 --smooth-wall 0.25 \
  --out $D/energy/n2075_smooth025.json
run d_n5283_smooth025 reproductions/lib/alaric_fig8_isolate.py fresh --n 5283 --split 0 --smooth-wall 0.25 --max-steps 800 \
  --max-wall 420 --every 100 --out $D/d_n5283_smooth025
# (b) the N = 9625 split-1 run again with the smooth wall (L = 0.5), from the start (started 10:34, after the rest)
run b_n9625_split1_smooth05 reproductions/lib/alaric_fig8_isolate.py fresh --n 9625 --split 1 --smooth-wall 0.5 \
  --max-steps 3000 --max-wall 840 --every 100 --out $D/b_n9625_split1_smooth05
# (f) a fresh run at the paper's N = 26 411 (split 0) with the smooth wall (L = 0.5), 14-min cap (started 10:39)
run f_n26411_smooth05 reproductions/lib/alaric_fig8_isolate.py fresh --n 26411 --split 0 --smooth-wall 0.5 --max-steps 20000 \
  --max-wall 840 --every 100 --out $D/f_n26411_smooth05
# the table and results.json
python reproductions/alaric-fig8-3d-isolate/table.py $D > $D/table.md
