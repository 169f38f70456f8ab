#!/usr/bin/env bash
# Failure states (clustering.failure_states: a failure observed outside its nearest state's
# zone of influence becomes a state of its own). Why: in the paper's protocol with one-sided
# revisions, half the runs kept colliding in a state of safe driving 50-70 m behind the lead,
# which eTS+ never split because a rare failure never tops or undercuts the potentials.
# SEED=4 (default) or 5, STOP_AFTER, EPISODES: as results/scripts/against-default.sh says; writes
# results/tuning/failure-states.
# Recorded against the default of its time (knee off): commit 7cf2170 regenerates the rows;
# later code refuses to extend them.
BASELINE=one-sided exec "$(dirname "$0")/against-default.sh" failure-states \
    '{"clustering": {"failure_states": true}}'
