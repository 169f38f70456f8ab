#!/usr/bin/env bash
# Flags per entry at a lower rate, 0.03 instead of 0.05 (results/scripts/entry-rate.sh). Why: on tuning
# seed 5 the recurring failure is a broad state at contact that stays just under 0.05 (57
# crashes in 1,155 entries, 4.9%) while ordinary driving saw a crash in 0.6-4.5% of its entries
# on tuning seed 6. SEED=4 (default) or 5, STOP_AFTER, EPISODES: as results/scripts/against-default.sh
# says; compared with results/scripts/entry-rate.sh's rows (BASELINE=entry-rate); writes
# results/tuning/entry-rate-0.03.
BASELINE=${BASELINE:-entry-rate} exec "$(dirname "$0")/against-default.sh" entry-rate-0.03 \
    '{"reviser": {"flag_rate_per": "entry", "flag_min_rate": 0.03}}'
