#!/usr/bin/env bash
# A two-step prediction on the default then (count-based flags, the double knee). Why: a
# revision comes when the next step's prediction (0.25 s ahead) reaches a flagged state, too
# late when closing fast (results/README.md, "Sticky flags, or flags per entry"); with sticky
# flags a second step of the marginal TPM (spec A11) cut collisions early on a tuning seed
# (results/scripts/sticky-horizon.sh), but sticky flags themselves left four of ten runs of the
# paper's protocol falling behind (results/README.md, "The paper's protocol with sticky
# flags"). This tries the horizon with the flags that lift.
# SEED=4 (default) or 5, STOP_AFTER, EPISODES: as results/scripts/against-default.sh says; writes
# results/tuning/horizon-2.
# Recorded against the default of its time (flags per recognition at 0.002): commit 2cac6a3
# regenerates the rows; later code refuses to extend them.
BASELINE=knee-double exec "$(dirname "$0")/against-default.sh" horizon-2 '{"reviser": {"horizon": 2}}'
