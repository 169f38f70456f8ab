#!/usr/bin/env bash
# DDPG's intervention penalty: the learner also remembers the proposal the shield replaced,
# with the step's reward less the penalty, so that it learns to avoid what the shield replaces
# instead of leaning on it. Tuning seed 4 (2 runs x 200 episodes, one lockstep group a row),
# penalties 2 and 0.5, with and without a failure penalty of 60 in the reward, beside the
# default shield with neither; then the chosen penalty (0.5, no failure penalty) on the
# evaluation seeds (the reduced protocol: base seed 1000, 4 runs x 600). Resumable: run it
# again to go on. Records and tables in results/tuning/intervention-penalty and
# results/reduced/intervention-penalty. The penalty lost and was removed after commit f18c10b:
# run this script there.
set -euo pipefail
cd "$(dirname "$0")/../.."
source scripts/_venv.sh
tune=results/tuning/intervention-penalty
for row in 'ip2:2:{}' 'ip2-fp60:2:{"failure_penalty": 60}' 'ip05:0.5:{}' \
           'ip05-fp60:0.5:{"failure_penalty": 60}'; do
    IFS=: read -r name penalty reward <<<"$row"
    .venv/bin/python -m client run --arms ddpg+shield --runs 2 --episodes 200 --seed 4 \
        --lockstep --workers 1 --reward "$reward" --ddpg "{\"intervention_penalty\": $penalty}" \
        --out "$tune/$name" >/dev/null
done
.venv/bin/python -m client compare results/tuning/risk-reviser/seed-4/risk-default \
    results/tuning/failure-penalty/60-shield "$tune"/{ip2,ip2-fp60,ip05,ip05-fp60} --blocks \
    --out "$tune/table.md"
evaluation=results/reduced/intervention-penalty
.venv/bin/python -m client run --arms ddpg+shield --runs 4 --episodes 600 --seed 1000 \
    --shield local --lockstep --workers 1 --ddpg '{"intervention_penalty": 0.5}' \
    --out "$evaluation/ip05" >/dev/null
.venv/bin/python -m client compare results/reduced/failure-penalty/60 \
    results/reduced/default-switch/risk-default "$evaluation/ip05" --blocks \
    --out results/reduced/intervention-penalty.md
