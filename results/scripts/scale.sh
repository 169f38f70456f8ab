#!/usr/bin/env bash
# Tuning of the headway scale (base seeds 0-2, never the evaluation seeds), in-process shields,
# 2 runs x 250 episodes per row: the headway normalised by 100, 50 and 25 m on seed 0, by 200 m
# and 50 m on seeds 1 and 2 where no 200 m row of results/scripts/tuning.sh exists, and 50 m with the
# revision noise almost gone (K = 1) on all three; and 50 m with sticky flags on all three,
# after the trace of seed 1 showed count-based flags leaving a busy crash state unflagged. One table, results/tuning/scale/scale.md, beside the
# 200 m rows and DDPG alone of results/scripts/tuning.sh. Resumable: finished experiments are skipped.
set -euo pipefail
cd "$(dirname "$0")/../.."
source scripts/_venv.sh
experiments() {  # OUT SEED, then lines "NAME;ARM;SHIELD-OVERRIDES" on stdin
    while IFS=';' read -r name arm overrides; do
        .venv/bin/python -m client run --arms "$arm" --shield-config "$overrides" \
            --out "$1/$name" --runs 2 --episodes 250 --seed "$2" --shield local \
            --workers 2 >/dev/null
    done
}
out=results/tuning/scale
h200='{"observation": {"high": [32.0, 200.0, 32.0]}}'
h50='{"observation": {"high": [32.0, 50.0, 32.0]}}'
h50k1='{"observation": {"high": [32.0, 50.0, 32.0]}, "reviser": {"noise_k": 1.0}}'
h50sticky='{"observation": {"high": [32.0, 50.0, 32.0]}, "reviser": {"flags": "sticky"}}'
experiments "$out" 0 <<JOBS
headway-100;ddpg+shield;{"observation": {"high": [32.0, 100.0, 32.0]}}
headway-50;ddpg+shield;$h50
headway-25;ddpg+shield;{"observation": {"high": [32.0, 25.0, 32.0]}}
headway-50-noise-k-1;ddpg+shield;$h50k1
headway-50-sticky;ddpg+shield;$h50sticky
JOBS
experiments "$out/seed-1" 1 <<JOBS
headway-50;ddpg+shield;$h50
headway-50-noise-k-1;ddpg+shield;$h50k1
headway-50-sticky;ddpg+shield;$h50sticky
JOBS
experiments "$out/seed-2" 2 <<JOBS
ddpg;ddpg;{}
headway-200;ddpg+shield;$h200
headway-50;ddpg+shield;$h50
headway-50-noise-k-1;ddpg+shield;$h50k1
headway-50-sticky;ddpg+shield;$h50sticky
JOBS
.venv/bin/python -m client compare results/tuning/switches/{ddpg,default} \
    "$out"/{headway-100,headway-50,headway-25,headway-50-noise-k-1,headway-50-sticky} \
    results/tuning/seed-1/{ddpg,default} \
    "$out"/seed-1/{headway-50,headway-50-noise-k-1,headway-50-sticky} \
    "$out"/seed-2/{ddpg,headway-200,headway-50,headway-50-noise-k-1,headway-50-sticky} \
    --out "$out/scale.md"
