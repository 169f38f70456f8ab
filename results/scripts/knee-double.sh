#!/usr/bin/env bash
# A knee that leaves the far range as it is (observation.knee_shape "double": every metre of
# headway within 20 m of the lead counts twice, the far range keeps the 50 m scale). Why: the
# log knee (results/scripts/knee.sh) gave the crashes states of their own but made far headways
# coarser, and seed 4 lost more runs to large distances early. SEED=4 (default) or 5,
# STOP_AFTER, EPISODES: as results/scripts/against-default.sh says; writes results/tuning/knee-double.
# Recorded against the default of its time (flags per recognition at 0.002): commit 2cac6a3
# regenerates the rows; later code refuses to extend them.
BASELINE=one-sided exec "$(dirname "$0")/against-default.sh" knee-double \
    '{"observation": {"knee": [0.0, 20.0, 0.0], "knee_shape": "double"}}'
