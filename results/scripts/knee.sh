#!/usr/bin/env bash
# A knee on the headway (observation.knee: the headway through 20 ln(1 + h / 20) before the
# 50 m scale, so close following spans about twice as much of the clustering space and the
# far range less). Why: in the failure-states runs most collisions fell in broad states of
# close following (centres 0-7 m behind the lead, tens of thousands of recognitions), whose
# collision rate stays under the flag; a finer split of close following may give the seconds
# before a crash states of their own. SEED=4 (default) or 5, STOP_AFTER, EPISODES: as
# results/scripts/against-default.sh says; writes results/tuning/knee.
# Recorded before knee_shape existed, with the log shape, and against the default of its time
# (knee off): commit 7cf2170 regenerates the rows; later code refuses to extend them.
BASELINE=one-sided exec "$(dirname "$0")/against-default.sh" knee \
    '{"observation": {"knee": [0.0, 20.0, 0.0]}}'
