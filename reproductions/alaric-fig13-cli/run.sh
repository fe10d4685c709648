#!/bin/sh
# Fig. 13 from the CLI's default start (a jittered lattice in the circle, thinned to N): the command with
# every other option at its default (convex edge file: mirror ghosts, log potential), and the same with
# --finish squares. circle.edges: the unit circle as a regular 256-gon. Run from the repository root.
sphrelax density --profile uniform --dim 2 --n 2000 --split 0 --domain reproductions/alaric-fig13-cli/results/circle.edges \
  --seed 0 --max-steps 10000 --form log --out reproductions/alaric-fig13-cli/results/default --overwrite \
  > reproductions/alaric-fig13-cli/results/default.log 2>&1
sphrelax density --profile uniform --dim 2 --n 2000 --split 0 --domain reproductions/alaric-fig13-cli/results/circle.edges \
  --seed 0 --max-steps 10000 --finish squares --form log --out reproductions/alaric-fig13-cli/results/finish_squares --overwrite \
  > reproductions/alaric-fig13-cli/results/finish_squares.log 2>&1
