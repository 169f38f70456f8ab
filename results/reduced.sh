#!/usr/bin/env bash
# The reduced protocol of results/README.md: 2 runs x 300 episodes per arm on the evaluation
# seeds (base seed 1000), in-process shields, CMAP training traces. Resumable: run it again to
# continue an interrupted experiment. Needs the environment of scripts/_venv.sh.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/_venv.sh
out=results/reduced
common=(--runs 2 --episodes 300 --seed 1000 --shield local --workers 2)
run() {  # NAME ARMS SHIELD-OVERRIDES
    .venv/bin/python -m client run --arms "$2" --shield-config "$3" --out "$out/$1" "${common[@]}" >/dev/null
}
run ddpg ddpg '{}'
run default ddpg+shield '{}'
run flags-sticky ddpg+shield '{"reviser": {"flags": "sticky"}}'
run flags-overwrite ddpg+shield '{"reviser": {"flags": "overwrite"}}'
run inspect-first-index ddpg+shield '{"reviser": {"inspect": "first_index"}}'
run new-state-pad ddpg+shield '{"transitions": {"on_new_state": "pad"}}'
run noise-std ddpg+shield '{"reviser": {"noise": "std"}}'
run no-transpose ddpg+shield '{"reviser": {"transpose": false}}'
run horizon-2 ddpg+shield '{"reviser": {"horizon": 2}}'
run other-controllers idm-aggressive,idm-aggressive+shield,random,random+shield '{}'
.venv/bin/python -m client compare "$out"/{ddpg,default,flags-sticky,flags-overwrite,inspect-first-index,new-state-pad,noise-std,no-transpose,horizon-2} --out "$out/ablations.md"
.venv/bin/python -m client report "$out/other-controllers" >/dev/null
