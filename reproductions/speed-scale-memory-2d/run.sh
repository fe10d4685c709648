#!/bin/sh
# The rows of this entry (from the repository root; about 20 minutes on one core). rows_before.json and
# rows_copy_chunk*.json were made by the same run.py in `git archive` copies of c5d123d and of 385299d with the
# neighbors.py change of the README (see it), rows_after.json at 385299d; this script remakes the rows of the
# checkout it runs in (rows_final.json: the commit that took the chunked copy).
set -e
R=reproductions/speed-scale-memory-2d/results
ROWS="bipi2d:1e4:list,bipi2d:1e4:list,bipi2d:1e4:list,bipi2d:3e4:list,bipi2d:3e4:list,bipi2d:3e4:list,alaric2d:1e4:list,alaric2d:1e4:list,alaric2d:1e4:list,alaric2d:3e4:list,alaric2d:3e4:list,alaric2d:3e4:list"
NUMBA_NUM_THREADS=1 python reproductions/speed-scale-memory-alaric/run.py \
    --rows $ROWS,bipi2d:1e5:list,bipi2d:1e5:list,bipi2d:1e5:list,alaric2d:1e5:list,alaric2d:1e5:list,alaric2d:1e5:list \
    --out $R/rows_final.json
NUMBA_NUM_THREADS=1 python reproductions/speed-scale-memory-2d/ab.py \
    alaric2d:1e4:8:20:release,bipi2d:1e4:8:20:release,bipi2d:1e4:8:20:threshold,bipi2d:1e5:6:5:threshold > $R/ab.json
python reproductions/speed-scale-memory-2d/summarise.py
