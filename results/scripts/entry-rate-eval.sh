#!/usr/bin/env bash
# Flags per entry on the evaluation seeds, after tuning seeds 4 and 5 (results/scripts/entry-rate.sh,
# results/scripts/entry-rate-low.sh): 4 runs x 300 episodes per row, base seed 1000, in-process
# shields, one lockstep group per row, both rows at once. Read against results/scripts/reduced-4.sh's
# rows of DDPG alone and of the double knee (the default then; recorded on an earlier 2-core
# machine, without lockstep). Rows: per entry at 0.05 (ddpg-shield-entry-rate) and at 0.03
# (ddpg-shield-entry-rate-0.03). One table: results/reduced/four-runs/entry-rate.md.
# Resumable: finished rows are read, not rerun.
set -euo pipefail
cd "$(dirname "$0")/../.."
source scripts/_venv.sh
out=results/reduced/four-runs
run() {  # run OUT RATE
    .venv/bin/python -m client run --arms ddpg+shield --out "$out/$1" --runs 4 --episodes 300 \
        --seed 1000 --shield local --lockstep --workers 1 \
        --shield-config "{\"reviser\": {\"flag_rate_per\": \"entry\", \"flag_min_rate\": $2}}" \
        >/dev/null
}
run ddpg-shield-entry-rate 0.05 &
first=$!
run ddpg-shield-entry-rate-0.03 0.03
wait "$first"
.venv/bin/python -m client compare \
    "$out"/{ddpg,ddpg-shield-knee-double,ddpg-shield-entry-rate,ddpg-shield-entry-rate-0.03} \
    --blocks --out "$out/entry-rate.md"
