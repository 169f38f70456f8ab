#!/usr/bin/env bash
# Count-based flags per entry with a two-step prediction, against flags per entry alone (both
# on the double knee, the default then). Why: a two-step prediction helped sticky flags on
# tuning seed 4 (89.3% against 86.7%) and not today's count-based flags, whose flags lift
# sooner when the shield keeps the car out of flagged states (results/README.md, "A two-step
# prediction"). Flags per entry held the states of crashes and lifted those of ordinary
# following on seeds 4 and 5, as sticky flags did not in the paper's protocol: the question is
# whether they keep the horizon's gain without sticky flags' cost.
# SEED=4 (default) or 5, STOP_AFTER, EPISODES: as results/scripts/against-default.sh says; writes
# results/tuning/entry-horizon-2.
BASELINE=entry-rate exec "$(dirname "$0")/against-default.sh" entry-horizon-2 \
    '{"reviser": {"flag_rate_per": "entry", "flag_min_rate": 0.05, "horizon": 2}}'
