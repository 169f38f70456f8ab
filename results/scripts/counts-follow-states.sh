#!/usr/bin/env bash
# Issue #44 with the default of commit 187d875 (outcome counts that follow the states, the risk
# reviser acting from the first episode): DDPG, 2 runs x 200 episodes on tuning seeds 4-6 and
# 2 x 600 on tuning seed 8 (where a run kept falling behind late), then the reduced protocol on
# the evaluation seeds (4 runs x 600, base seed 1000) beside the arms of default-switch.sh.
# One lockstep group an arm, in-process shields. Resumable: run it again to go on.
set -euo pipefail
cd "$(dirname "$0")/../.."
source scripts/_venv.sh
run() {  # OUT SEED RUNS EPISODES
    .venv/bin/python -m client run --arms ddpg+shield --out "$1" --seed "$2" --runs "$3" \
        --episodes "$4" --shield local --lockstep --workers 1 >/dev/null
    echo "done: $1"
}
tuning=results/tuning/counts-follow-states
if [ "${PART:-all}" != evaluation ]; then
    for seed in 4 5 6; do run "$tuning/seed-$seed" "$seed" 2 200; done
    run "$tuning/seed-8" 8 2 600
fi
if [ "${PART:-all}" != tuning ]; then
    out=results/reduced/counts-follow-states
    run "$out/risk-default" 1000 4 600
    .venv/bin/python -m client compare "$out/risk-default" \
        results/reduced/default-switch/{risk-default,paper} --blocks \
        --out results/reduced/counts-follow-states.md
fi
