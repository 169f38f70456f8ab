#!/usr/bin/env bash
# Issue #44, the reach (the default since commit 3b0d632): DDPG 2 runs x 200 episodes on tuning
# seeds 4-6, then the reduced protocol on the evaluation seeds (4 runs x 600, base seed 1000)
# beside the local model with support alone (results/reduced/local-support/). One lockstep
# group an arm, in-process shields, checkpoints every 5 minutes. Resumable: run it again to go
# on.
set -euo pipefail
cd "$(dirname "$0")/../.."
source scripts/_venv.sh
run() {  # OUT SEED RUNS EPISODES
    .venv/bin/python -m client run --arms ddpg+shield --out "$1" --seed "$2" --runs "$3" \
        --episodes "$4" --shield local --lockstep --workers 1 --checkpoint-minutes 5 >/dev/null
    echo "done: $1"
}
if [ "${PART:-all}" != evaluation ]; then
    for seed in 4 5 6; do run "results/tuning/reach/seed-$seed" "$seed" 2 200; done
fi
if [ "${PART:-all}" != tuning ]; then
    out=results/reduced/reach
    run "$out/local" 1000 4 600
    .venv/bin/python -m client compare "$out/local" results/reduced/local-support/local \
        --blocks --out results/reduced/reach.md
fi
