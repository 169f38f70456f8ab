#!/usr/bin/env bash
# Failure states (clustering.failure_states: a failure observed outside its nearest state's
# zone of influence becomes a state of its own). Why: in the paper's protocol with one-sided
# revisions, half the runs kept colliding in a state of safe driving 50-70 m behind the lead,
# which eTS+ never split because a rare failure never tops or undercuts the potentials.
# Tuning seeds (never the evaluation seeds), 4 runs x 600 episodes in one lockstep group,
# in-process shields, as results/one-sided.sh, whose rows (the default since) are the baseline.
# SEED=4 (default) or 5; STOP_AFTER=M stops after M minutes (it goes on from its checkpoint
# when run again). Writes results/tuning/failure-states/seed-$SEED and one table per seed,
# failure-states-seed-$SEED.md (EPISODES=N: each run's first N episodes).
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/_venv.sh
seed=${SEED:-4}
out=results/tuning/failure-states
.venv/bin/python -m client run --arms ddpg+shield \
    --shield-config '{"clustering": {"failure_states": true}}' \
    --out "$out/seed-$seed" --runs 4 --episodes 600 --seed "$seed" --shield local --lockstep \
    --workers 1 ${STOP_AFTER:+--stop-after "$STOP_AFTER"} >/dev/null
.venv/bin/python -m client compare results/tuning/one-sided/seed-$seed "$out/seed-$seed" \
    ${EPISODES:+--episodes "$EPISODES"} --out "$out/failure-states-seed-$seed.md"
