#!/usr/bin/env bash
# Sticky flags with a two-step prediction, against sticky flags alone (both on the double
# knee, the default then). Why: with sticky flags the shield went on revising late in training
# and led on both tuning seeds, but in one run it crashed 47 times in 100 episodes, every crash
# in a state flagged for it: a one-step prediction (0.25 s) sees the flagged state only when
# the car is already in it or next to it, while closing at 17 m/s needs some 35 steps of full
# braking (results/README.md, "Sticky flags, or flags per entry"). A second step of the
# marginal TPM (spec A11) looks one step further, on every action's transitions.
# SEED=4 (default) or 5, STOP_AFTER, EPISODES: as results/scripts/against-default.sh says; writes
# results/tuning/sticky-horizon-2.
BASELINE=sticky-knee exec "$(dirname "$0")/against-default.sh" sticky-horizon-2 \
    '{"reviser": {"flags": "sticky", "horizon": 2}}'
