#!/bin/sh
# The serial queue of the small controlled runs (one at a time, niced, one thread), run from the repository root
# after a_n2075_split0 (README). Each run's load averages at start and end go to <name>.uptime.
D=examples/results/alaric/fig8_3d_isolate
PY="env OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 PYTHONPATH=$PWD nice -n 10 /work/main/.venv/bin/python"
run() { name=$1; shift; uptime > $D/$name.uptime; $PY "$@" > $D/$name.log 2>&1; uptime >> $D/$name.uptime; }
# (a) N = 2075, split 1 (the control fig8_mirror/3d_n2075_after, with the caps of a_n2075_split0)
run a_n2075_split1 -m ase_sphrelax.cli density --profile eq46 --delta 0.01 --dim 3 --n 2075 --split 1 \
  --max-steps 6000 --max-wall 600 --out $D/a_n2075_split1 --overwrite
# (b) N = 9625 = 77 * 5^3 with one splitting stage (stage 0: 1925 particles, at most 1500 steps), tracked
run b_n9625_split1 examples/alaric_fig8_isolate.py fresh --n 9625 --split 1 --max-steps 3000 --max-wall 900 \
  --every 100 --out $D/b_n9625_split1
# (d) one ingredient at a time at N = 5283, split 0, 800 steps, against e_n26415_split1's stage 0 (the same start and
# dynamics: mirror ghosts, CFL 0.25, viscosity, velocity stops, eta 3): truncated kernels (wall), a smaller time
# step (CFL 0.1), no artificial viscosity, more neighbours (eta 3.6)
run d_n5283_wall examples/alaric_fig8_isolate.py fresh --n 5283 --split 0 --boundary wall --max-steps 800 \
  --max-wall 480 --every 100 --out $D/d_n5283_wall
run d_n5283_cfl01 examples/alaric_fig8_isolate.py fresh --n 5283 --split 0 --cfl 0.1 --max-steps 800 \
  --max-wall 480 --every 100 --out $D/d_n5283_cfl01
run d_n5283_novisc examples/alaric_fig8_isolate.py fresh --n 5283 --split 0 --no-viscosity --max-steps 800 \
  --max-wall 480 --every 100 --out $D/d_n5283_novisc
run d_n5283_eta36 examples/alaric_fig8_isolate.py fresh --n 5283 --split 0 --eta 3.6 --max-steps 800 \
  --max-wall 480 --every 100 --out $D/d_n5283_eta36
# (c) continuation of the N = 26 411 split-0 state (fig8_mirror/3d_n26411), zero start velocities
run c_n26411_continue examples/alaric_fig8_isolate.py continue examples/results/alaric/fig8_mirror/3d_n26411 \
  --max-steps 20000 --max-wall 600 --every 50 --out $D/c_n26411_continue
