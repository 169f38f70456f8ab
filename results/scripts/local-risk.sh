#!/usr/bin/env bash
# Issue #44, the local risk model (`risk.model: local`, horizon 24; opt-in at commit a7e0261 and
# after): DDPG, 2 runs x 600 episodes on tuning seed 8 and 2 x 200 on tuning seeds 4-6, then
# the reduced protocol on the evaluation seeds (4 runs x 600, base seed 1000) beside the arms
# of counts-follow-states.sh. One lockstep group an arm, in-process shields, checkpoints every
# 5 minutes. Resumable: run it again to go on.
set -euo pipefail
cd "$(dirname "$0")/../.."
source scripts/_venv.sh
LOCAL='{"risk": {"model": "local", "horizon": 24}}'
run() {  # OUT SEED RUNS EPISODES
    .venv/bin/python -m client run --arms ddpg+shield --out "$1" --seed "$2" --runs "$3" \
        --episodes "$4" --shield local --shield-config "$LOCAL" --lockstep --workers 1 \
        --checkpoint-minutes 5 >/dev/null
    echo "done: $1"
}
tuning=results/tuning/local-risk
if [ "${PART:-all}" != evaluation ]; then
    run "$tuning/seed-8" 8 2 600
    for seed in 4 5 6; do run "$tuning/seed-$seed" "$seed" 2 200; done
fi
if [ "${PART:-all}" != tuning ]; then
    out=results/reduced/local-risk
    run "$out/local" 1000 4 600
    .venv/bin/python -m client compare "$out/local" \
        results/reduced/counts-follow-states/risk-default --blocks \
        --out results/reduced/local-risk.md
fi
