#!/usr/bin/env bash
# The reduced protocol of results/README.md: 2 runs x 300 episodes per arm on the evaluation
# seeds (base seed 1000), in-process shields, CMAP training traces; two experiments at a time.
# Resumable: run it again to continue an interrupted experiment (finished ones are skipped).
set -euo pipefail
cd "$(dirname "$0")/../.."
source scripts/_venv.sh
export out=results/reduced
experiment() {  # "NAME;ARMS;SHIELD-OVERRIDES"
    IFS=';' read -r name arms overrides <<<"$1"
    .venv/bin/python -m client run --arms "$arms" --shield-config "$overrides" \
        --out "$out/$name" --runs 2 --episodes 300 --seed 1000 --shield local --workers 1 \
        >/dev/null
    echo "done: $name"
}
export -f experiment
xargs -P 2 -d '\n' -I{} bash -c 'experiment "$1"' _ {} <<'JOBS'
ddpg;ddpg;{}
default;ddpg+shield;{}
flags-sticky;ddpg+shield;{"reviser": {"flags": "sticky"}}
flags-overwrite;ddpg+shield;{"reviser": {"flags": "overwrite"}}
inspect-first-index;ddpg+shield;{"reviser": {"inspect": "first_index"}}
new-state-pad;ddpg+shield;{"transitions": {"on_new_state": "pad"}}
noise-std;ddpg+shield;{"reviser": {"noise": "std"}}
no-transpose;ddpg+shield;{"reviser": {"transpose": false}}
horizon-2;ddpg+shield;{"reviser": {"horizon": 2}}
headway-50;ddpg+shield;{"observation": {"high": [32.0, 50.0, 32.0]}}
other-controllers;idm-aggressive,idm-aggressive+shield,random,random+shield;{}
JOBS
.venv/bin/python -m client compare "$out"/{ddpg,default,flags-sticky,flags-overwrite,inspect-first-index,new-state-pad,noise-std,no-transpose,horizon-2,headway-50} \
    --out "$out/ablations.md"
.venv/bin/python -m client report "$out/other-controllers" >/dev/null
