#!/bin/sh
# ALARIC 2D/3D peak memory per particle from 1e4 to 1e6 (bench_scale.py's step child). The diagnostic of where the
# peak goes: python reproductions/speed-scale-memory-alaric/profile.py --method alaric2d --n 1e5 [--trim|--inventory]
#     --out FILE (see the README).
set -e
export NUMBA_NUM_THREADS=1
python benchmarks/bench_scale.py --methods alaric2d,alaric3d --sizes 1e4,1e5,1e6 --max-step-1e6 60 --no-quality \
    --out benchmarks/results/bench_scale_alaric_mem.json
