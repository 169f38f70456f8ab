#!/usr/bin/env bash
# The failure penalty on the evaluation seeds: the reduced protocol (base seed 1000, 4 runs x
# 600 episodes, one lockstep group per row, in-process shields), DDPG with the default shield
# and DDPG alone with a penalty of 60, beside the risk default without one
# (results/reduced/default-switch/risk-default). Why: on tuning seed 4 the penalty
# took DDPG alone from 17.5% to 88.5% in episodes 101-200 (results/tuning/failure-penalty);
# whether it ends the evaluation runs' late falling behind decides whether it becomes the
# default. Resumable: run it again to go on. Records and the table in
# results/reduced/failure-penalty.
set -euo pipefail
cd "$(dirname "$0")/../.."
source scripts/_venv.sh
out=results/reduced/failure-penalty
for row in '60-shield:ddpg+shield:{"failure_penalty": 60}' '60:ddpg:{"failure_penalty": 60}'; do
    IFS=: read -r name arm reward <<<"$row"
    .venv/bin/python -m client run --arms "$arm" --runs 4 --episodes 600 --seed 1000 \
        --shield local --lockstep --workers 1 --reward "$reward" --out "$out/$name" >/dev/null
    echo "done: $name"
done
.venv/bin/python -m client compare "$out/60" results/reduced/default-switch/risk-default \
    "$out/60-shield" --blocks \
    --out results/reduced/failure-penalty.md
