#!/bin/bash
# Every part of results.json, in the order of README.md's table (~30 min in all). The NUTS reference is made on the
# first use (reproductions/lib/parvi_reference.py, a few minutes). The script pins the sampler defaults the results
# were made with (reproductions/lib/parvi_pinned.py).
set -e
cd "$(dirname "$0")/../.."   # the repository root
export OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 PYTHONPATH=$PWD
RUN="nice -n 10 ${PYTHON:-python} reproductions/parvi-logistic-goal/run.py"
$RUN goal
$RUN gauss10d --repeats 1
$RUN gauss10d --repeats 3 --tag seeds3
$RUN rest
$RUN gauss32 --repeats 1 --steps 1000
$RUN k
$RUN m --sizes 100 2000
$RUN iid
$RUN goal --sizes 500 --steps 0 --variant knn+whiten+mala+finish_steps=500 --tag mala_only
$RUN goal --sizes 2000 --repeats 1 --tag m2000
$RUN goal --sizes 2000 --repeats 3 --tag m2000_r3
$RUN spread
