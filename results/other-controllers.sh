#!/usr/bin/env bash
# The shield in front of controllers it was not built around, with today's default (epsilon
# 0.15, headway by 50 m, count-based flags): the IDM follower, an aggressive IDM and the random
# controller, each with and without the shield. Evaluation seeds (base seed 1000), 4 runs x 300
# episodes per arm, in-process shields, CMAP training traces; one table,
# results/reduced/other-controllers-eps-0.15/table.md. (reduced/other-controllers is the same
# question at the 200 m scale and epsilon 0.3, 2 runs an arm.) Resumable.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/_venv.sh
.venv/bin/python -m client run --out results/reduced/other-controllers-eps-0.15 \
    --arms idm,idm+shield,idm-aggressive,idm-aggressive+shield,random,random+shield \
    --runs 4 --episodes 300 --seed 1000 --shield local --workers 1
