#!/usr/bin/env bash
# Failure centres on top of flags per entry (today's default): reviser.failure_centres keeps a
# state flagged while its centre is the observation of a failure. Why: late in the paper's
# protocol with flags per entry, 582 of the 719 collisions in states not flagged at the end
# were recognised in twelve states centred on a collision, entered so often without one
# (crashes in 0.3-4.3% of the entries) that their counted flag lifted, while states of
# ordinary following had rates as high (results/README.md, "Flags per entry at 0.05 in the
# paper's protocol"). SEED=4 (default) or 5, STOP_AFTER, EPISODES: as
# results/scripts/against-default.sh says; writes results/tuning/failure-centres.
exec "$(dirname "$0")/against-default.sh" failure-centres '{"reviser": {"failure_centres": true}}'
