#!/usr/bin/env bash
# Does the revision noise make the shield hurt a deterministic controller? With the default then
# the aggressive IDM follower collided more with the shield than without it on the evaluation
# seeds (reduced/other-controllers-eps-0.15), although every revision was a slower action:
# a revised action is the chosen bin's midpoint plus N(0, V), V = a_max / max(1, K episode),
# a standard deviation of 1.41 m/s^2 at the paper's K = 0.001. Tuning seed 4 (never the
# evaluation seeds), 4 runs x 300 episodes per row, in-process shields: the aggressive IDM
# alone and with the default shield, and with K = 1000 (the noise gone: std below 0.01 m/s^2
# from episode 51, when the reviser starts), and with one-sided revisions (never faster than
# the proposal against a collision). One table, results/tuning/idm-noise/idm-noise.md;
# then the default row's runs 0 and 1 again with their step traces (run 1 is the one where the
# shield revised) and what `client trace` says of them (trace/trace.md). Resumable.
set -euo pipefail
cd "$(dirname "$0")/../.."
source scripts/_venv.sh
out=results/tuning/idm-noise
run() {  # NAME ARMS OVERRIDES [OPTIONS]
    .venv/bin/python -m client run --arms "$2" --shield-config "$3" --out "$out/$1" \
        --episodes 300 --seed 4 --shield local --workers 1 "${@:4}" >/dev/null
}
run default idm-aggressive,idm-aggressive+shield '{}' --runs 4
run noise-k-1000 idm-aggressive+shield '{"reviser": {"noise_k": 1000}}' --runs 4
run one-sided idm-aggressive+shield '{"reviser": {"one_sided": true}}' --runs 4
.venv/bin/python -m client compare "$out"/{default,noise-k-1000,one-sided} \
    --out "$out/idm-noise.md"
run trace idm-aggressive+shield '{}' --runs 2 --trace
.venv/bin/python -m client trace "$out/trace" >/dev/null
