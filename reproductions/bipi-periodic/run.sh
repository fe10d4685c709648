#!/bin/sh
# BIPI Sec. 4.2.2 / Figs. 19-21 (packing only): one period of the cylinder array, periodic in x.
# Run from the repository root: sh reproductions/bipi-periodic/run.sh  (about 25 s)
# sphrelax pack exits 3 here (Step 2c reaches its cap before its 1 % rule); the script goes on.
set -u
D=reproductions/bipi-periodic
python $D/make_edges.py
python -m ase_sphrelax.cli pack --method bipi --boundary $D/results/cylinder_array.edges --dx 0.0025 \
    --h 4 --periodic x --out $D/results/run --no-progress > $D/results/run/stdout.txt 2>&1
echo "rc=$?" >> $D/results/run/stdout.txt
gzip -9nf $D/results/run/summary.json
python $D/seam.py
