#!/usr/bin/env bash
# Tuning (base seed 0, never the evaluation seeds), in-process shields, one table per question.
#   1. epsilon: 2 runs x 150 episodes of the shielded arm per candidate (results/tuning/tuning.md)
#   2. the switches that did better than the default on the reduced protocol, the rate of the
#      count-based flags, and DDPG alone: 2 runs x 250 episodes each
#      (results/tuning/switches/switches.md)
#   3. DDPG alone and the default again on two more tuning runs, base seed 1
#      (results/tuning/seed-1/seed-1.md)
#   4. the revision noise decaying sooner (K = 0.02) and almost at once (K = 1), against the
#      default and DDPG alone of part 2 (results/tuning/noise/noise.md)
# These ran when the default normalised the headway by 200 m: commit 1f428c5 regenerates them
# as they are (later code refuses their records as made under other defaults). The tuning of
# the scale that replaced it is results/scripts/scale.sh.
# Resumable: finished experiments are skipped.
set -euo pipefail
cd "$(dirname "$0")/../.."
source scripts/_venv.sh
experiments() {  # OUT EPISODES [SEED], then lines "NAME;ARM;SHIELD-OVERRIDES" on stdin
    while IFS=';' read -r name arm overrides; do
        .venv/bin/python -m client run --arms "$arm" --shield-config "$overrides" \
            --out "$1/$name" --runs 2 --episodes "$2" --seed "${3:-0}" --shield local \
            --workers 2 >/dev/null
    done
}
out=results/tuning
experiments "$out" 150 <<'JOBS'
default;ddpg+shield;{}
epsilon-0.1;ddpg+shield;{"clustering": {"epsilon": 0.1}}
epsilon-0.05;ddpg+shield;{"clustering": {"epsilon": 0.05}}
JOBS
.venv/bin/python -m client compare "$out"/{default,epsilon-0.1,epsilon-0.05} --out "$out/tuning.md"

out=results/tuning/switches
experiments "$out" 250 <<'JOBS'
default;ddpg+shield;{}
inspect-first-index;ddpg+shield;{"reviser": {"inspect": "first_index"}}
noise-std;ddpg+shield;{"reviser": {"noise": "std"}}
horizon-2;ddpg+shield;{"reviser": {"horizon": 2}}
flags-overwrite;ddpg+shield;{"reviser": {"flags": "overwrite"}}
flag-rate-0.001;ddpg+shield;{"reviser": {"flag_min_rate": 0.001}}
flag-rate-0.005;ddpg+shield;{"reviser": {"flag_min_rate": 0.005}}
ddpg;ddpg;{}
JOBS
.venv/bin/python -m client compare "$out"/{ddpg,default,inspect-first-index,noise-std,horizon-2} \
    "$out"/{flags-overwrite,flag-rate-0.001,flag-rate-0.005} \
    --out "$out/switches.md"

out=results/tuning/seed-1
experiments "$out" 250 1 <<'JOBS'
ddpg;ddpg;{}
default;ddpg+shield;{}
JOBS
.venv/bin/python -m client compare "$out"/{ddpg,default} --out "$out/seed-1.md"

out=results/tuning/noise
experiments "$out" 250 <<'JOBS'
noise-k-0.02;ddpg+shield;{"reviser": {"noise_k": 0.02}}
noise-k-1;ddpg+shield;{"reviser": {"noise_k": 1.0}}
JOBS
.venv/bin/python -m client compare results/tuning/switches/{ddpg,default} \
    "$out"/{noise-k-0.02,noise-k-1} --out "$out/noise.md"

