#!/usr/bin/env bash
# The shield in front of controllers it was not built around, with the default then (epsilon
# 0.15, headway by 50 m, count-based flags): the IDM follower, an aggressive IDM and the random
# controller, each with and without the shield; then the shielded arms again with one-sided
# revisions (tried on tuning seed 4 after the default shield hurt the aggressive IDM:
# results/scripts/idm-noise.sh). Evaluation seeds (base seed 1000), 4 runs x 300 episodes per arm,
# in-process shields, CMAP training traces; tables in results/reduced/other-controllers-eps-0.15
# and other-controllers-one-sided, both in other-controllers.md. (reduced/other-controllers is
# the same question at the 200 m scale and epsilon 0.3, 2 runs an arm.) Resumable.
set -euo pipefail
cd "$(dirname "$0")/../.."
source scripts/_venv.sh
out=results/reduced
run() {  # NAME ARMS OVERRIDES
    .venv/bin/python -m client run --out "$out/$1" --arms "$2" --shield-config "$3" \
        --runs 4 --episodes 300 --seed 1000 --shield local --workers 1 >/dev/null
}
run other-controllers-eps-0.15 \
    idm,idm+shield,idm-aggressive,idm-aggressive+shield,random,random+shield '{}'
run other-controllers-one-sided idm+shield,idm-aggressive+shield,random+shield \
    '{"reviser": {"one_sided": true}}'
.venv/bin/python -m client compare "$out"/other-controllers-{eps-0.15,one-sided} \
    --out "$out/other-controllers.md"
