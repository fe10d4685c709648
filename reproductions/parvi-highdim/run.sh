#!/bin/bash
# Every part of results.json, in the order of README.md's table (~2 h in all; some parts ran at older revisions,
# named there: gaussian10d_main, logistic_main, gaussian10d_m2000 before the bounded renewal, renewals2d_symmetric and
# gaussian10d_m2000_bounded at afea48d). The NUTS reference is made on the first use (reproductions/lib/parvi_reference.py).
# The script pins the sampler defaults the results were made with (reproductions/lib/parvi_pinned.py).
set -e
cd "$(dirname "$0")/../.."   # the repository root
export OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 PYTHONPATH=$PWD
RUN="nice -n 10 ${PYTHON:-python} reproductions/parvi-highdim/run.py"
$RUN timing
$RUN stationary
$RUN gaussian10d --sizes 100 500 --repeats 2 --configs knn knn+whiten knn-ratio+whiten+local
$RUN logistic --sizes 100 500 --configs knn knn+whiten "knn+whiten(20,0.8)" knn-ratio+whiten+local
$RUN gaussian10d --sizes 2000 --configs knn knn+whiten --tag m2000
$RUN gaussian10d --sizes 100 500 --repeats 2 --configs knn+whiten+local --tag local
$RUN gaussian10d --sizes 2000 --configs knn-ratio+whiten+local --tag m2000_ratio
$RUN probes
$RUN renewals --sizes 100 --repeats 3
$RUN gaussian10d --sizes 100 500 --repeats 3 --configs knn+whiten knn-ratio+whiten+local --tag bounded
$RUN gaussian10d --sizes 2000 --repeats 2 --configs knn+whiten --tag m2000_bounded
$RUN ratio_weights
$RUN logistic --sizes 100 500 --repeats 2 --configs knn+whiten "knn-ratio+whiten(c0.15)" --tag bounded
$RUN logistic --sizes 500 --steps 3000 --configs "knn-ratio+whiten(c0.15)" --tag ratio3000
$RUN logistic --sizes 500 --steps 3000 --configs "knn-ratio+whiten(c0.15)" knn+whiten --tag kinetic3000
$RUN gaussian10d --sizes 2000 --configs knn+whiten --tag m2000_shrink
$RUN gaussian10d --sizes 2000 --configs knn+whiten --first-seed 1 --tag m2000_shrink_seed1
$RUN renewals2d --sizes 500
$RUN tables
