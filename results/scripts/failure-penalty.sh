#!/usr/bin/env bash
# DDPG alone, and DDPG with the default shield, with and without a failure penalty in the
# reward (tuning seed 4, 2 runs x 200 episodes, one lockstep group each). Why: every term of the paper's reward (Eqs. 10-12) is at
# most 0 and the critic values a terminal step at 0, so without a penalty ending an episode
# early by a failure is what DDPG learns to value most. 60 = 3 / (1 - 0.95): a failure costs as
# much as the worst reward for ever. Records and the table in results/tuning/failure-penalty.
set -euo pipefail
cd "$(dirname "$0")/../.."
source scripts/_venv.sh
out=results/tuning/failure-penalty
for row in "none:ddpg:{}" '60:ddpg:{"failure_penalty": 60}' \
           '60-shield:ddpg+shield:{"failure_penalty": 60}'; do
    IFS=: read -r name arm reward <<<"$row"
    .venv/bin/python -m client run --arms "$arm" --runs 2 --episodes 200 --seed 4 --lockstep \
        --workers 1 --reward "$reward" --out "$out/$name" >/dev/null
done
# the shield without a penalty on the same seed: the risk default's tuning row
.venv/bin/python -m client compare "$out/none" results/tuning/risk-reviser/seed-4/risk-default \
    "$out/60" "$out/60-shield" --blocks --out "$out/table.md"
