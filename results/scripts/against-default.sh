#!/usr/bin/env bash
# Shield overrides tried against today's default on a tuning seed: NAME CONFIG runs
# ddpg+shield with the overrides CONFIG (JSON), 4 runs x 600 episodes in one lockstep group
# with in-process shields, as results/scripts/entry-rate.sh, whose rows (the default) are the
# baseline; BASELINE=NAME compares with results/tuning/NAME's rows instead: knee-double (the
# default until commit 2cac6a3, against which flags per entry, sticky flags, the horizon and
# failure states on the knee were tried) or one-sided (until commit 7cf2170, against which
# the knees and failure states were tried).
# Tuning seeds only (never the evaluation seeds): SEED=4 (default) or 5. STOP_AFTER=M stops
# after M minutes (it goes on from its checkpoint when run again). Writes
# results/tuning/NAME/seed-$SEED and one table per seed, NAME-seed-$SEED.md (EPISODES=N: each
# run's first N episodes).
set -euo pipefail
cd "$(dirname "$0")/../.."
source scripts/_venv.sh
name=$1
config=$2
seed=${SEED:-4}
out=results/tuning/$name
.venv/bin/python -m client run --arms ddpg+shield --shield-config "$config" \
    --out "$out/seed-$seed" --runs 4 --episodes 600 --seed "$seed" --shield local --lockstep \
    --workers 1 ${STOP_AFTER:+--stop-after "$STOP_AFTER"} >/dev/null
.venv/bin/python -m client compare "results/tuning/${BASELINE:-entry-rate}/seed-$seed" \
    "$out/seed-$seed" ${EPISODES:+--episodes "$EPISODES"} --blocks --out "$out/$name-seed-$seed.md"
