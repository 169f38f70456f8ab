#!/usr/bin/env bash
# DDPG alone with and without a failure penalty in the reward (tuning seed 4, 2 runs x 200
# episodes, one lockstep group each). Why: every term of the paper's reward (Eqs. 10-12) is at
# most 0 and the critic values a terminal step at 0, so without a penalty ending an episode
# early by a failure is what DDPG learns to value most. 60 = 3 / (1 - 0.95): a failure costs as
# much as the worst reward for ever. Records and the table in results/tuning/failure-penalty.
set -euo pipefail
cd "$(dirname "$0")/../.."
source scripts/_venv.sh
out=results/tuning/failure-penalty
for row in "none:{}" '60:{"failure_penalty": 60}'; do
    .venv/bin/python -m client run --arms ddpg --runs 2 --episodes 200 --seed 4 --lockstep \
        --workers 1 --reward "${row#*:}" --out "$out/${row%%:*}" >/dev/null
done
.venv/bin/python -m client compare "$out/none" "$out/60" --blocks --out "$out/table.md"
