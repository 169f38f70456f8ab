#!/usr/bin/env bash
# A knee on the headway (observation.knee: the headway through 20 ln(1 + h / 20) before the
# 50 m scale, so close following spans about twice as much of the clustering space and the
# far range less). Why: in the failure-states runs most collisions fell in broad states of
# close following (centres 0-7 m behind the lead, tens of thousands of recognitions), whose
# collision rate stays under the flag; a finer split of close following may give the seconds
# before a crash states of their own.
# Tuning seeds (never the evaluation seeds), 4 runs x 600 episodes in one lockstep group,
# in-process shields, as results/one-sided.sh, whose rows (the default) are the baseline.
# SEED=4 (default) or 5; STOP_AFTER=M stops after M minutes (it goes on from its checkpoint
# when run again). Writes results/tuning/knee/seed-$SEED and one table per seed,
# knee-seed-$SEED.md (EPISODES=N: each run's first N episodes).
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/_venv.sh
seed=${SEED:-4}
out=results/tuning/knee
.venv/bin/python -m client run --arms ddpg+shield \
    --shield-config '{"observation": {"knee": [0.0, 20.0, 0.0]}}' \
    --out "$out/seed-$seed" --runs 4 --episodes 600 --seed "$seed" --shield local --lockstep \
    --workers 1 ${STOP_AFTER:+--stop-after "$STOP_AFTER"} >/dev/null
.venv/bin/python -m client compare results/tuning/one-sided/seed-$seed "$out/seed-$seed" \
    ${EPISODES:+--episodes "$EPISODES"} --out "$out/knee-seed-$seed.md"
