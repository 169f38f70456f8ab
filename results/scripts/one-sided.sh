#!/usr/bin/env bash
# One-sided revisions with DDPG (reviser.one_sided: a revision never accelerates more than the
# proposal against a collision, never less against falling behind; tried first with the
# aggressive IDM, results/scripts/idm-noise.sh). Tuning seeds (never the evaluation seeds), 4 runs x
# 600 episodes in one lockstep group, in-process shields, as results/scripts/flag-rate.sh, whose
# default rows (tuning/flag-rate/default for seed 4, tuning/flag-rate-seed-5/default for
# seed 5) are the baseline. SEED=4 (default) or 5; STOP_AFTER=M stops after M minutes (it
# goes on from its checkpoint when run again). Writes results/tuning/one-sided/seed-$SEED and
# one table per seed, one-sided-seed-$SEED.md (EPISODES=N: each run's first N episodes).
set -euo pipefail
cd "$(dirname "$0")/../.."
source scripts/_venv.sh
seed=${SEED:-4}
out=results/tuning/one-sided
baseline=results/tuning/flag-rate/default
if [[ $seed != 4 ]]; then baseline=results/tuning/flag-rate-seed-$seed/default; fi
.venv/bin/python -m client run --arms ddpg+shield --shield-config '{"reviser": {"one_sided": true}}' \
    --out "$out/seed-$seed" --runs 4 --episodes 600 --seed "$seed" --shield local --lockstep \
    --workers 1 ${STOP_AFTER:+--stop-after "$STOP_AFTER"} >/dev/null
.venv/bin/python -m client compare "$baseline" "$out/seed-$seed" ${EPISODES:+--episodes "$EPISODES"} \
    --out "$out/one-sided-seed-$seed.md"
