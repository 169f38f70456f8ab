#!/usr/bin/env bash
# Failure states on top of the double knee (the default then). Why: in the double knee's
# evaluation row, 50 of the 72 collisions of runs 2 and 3 were recognised in wide states of
# ordinary driving 61-107 m behind the lead, whose failure rate never reaches the flag
# (results/README.md, "A knee that keeps the far range"); clustering.failure_states makes a
# failure outside its nearest state's radius a state of its own, which may then win the crash's
# recognition. Tried without the knee it was level (results/scripts/failure-states.sh). SEED=4
# (default) or 5, STOP_AFTER, EPISODES: as results/scripts/against-default.sh says; writes
# results/tuning/failure-states-knee.
# Recorded against the default of its time (flags per recognition at 0.002): commit 2cac6a3
# regenerates the rows; later code refuses to extend them.
BASELINE=knee-double exec "$(dirname "$0")/against-default.sh" failure-states-knee \
    '{"clustering": {"failure_states": true}}'
