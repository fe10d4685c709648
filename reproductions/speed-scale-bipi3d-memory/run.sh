#!/bin/sh
# BIPI 3D (torus mesh, Step 2c) peak memory per particle and time per step, 1e4 to 1e6 (issue 33 item 4).
# The "before" file is the same command at commit f74b365 (--sizes 1e4,3e4,1e5, --out ..._before.json).
set -e
NUMBA_NUM_THREADS=1 nice -n 5 python benchmarks/bench_scale.py --methods bipi3d --sizes 1e4,3e4,1e5,1e6 \
    --max-step-1e6 60 --no-quality --out benchmarks/results/bench_scale_bipi3d_1e6.json
# the first run (numba cache cold at 1e4, 1e6 skipped) wrote benchmarks/results/bench_scale_bipi3d.json
