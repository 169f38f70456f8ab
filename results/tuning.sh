#!/usr/bin/env bash
# Tuning (base seed 0, never the evaluation seeds): 2 runs x 150 episodes of the shielded arm
# per candidate, in-process shields; then one table (results/tuning/tuning.md).
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/_venv.sh
out=results/tuning
while IFS=';' read -r name overrides; do
    .venv/bin/python -m client run --arms ddpg+shield --shield-config "$overrides" \
        --out "$out/$name" --runs 2 --episodes 150 --seed 0 --shield local --workers 2 >/dev/null
done <<'JOBS'
default;{}
epsilon-0.1;{"clustering": {"epsilon": 0.1}}
epsilon-0.05;{"clustering": {"epsilon": 0.05}}
JOBS
.venv/bin/python -m client compare "$out"/{default,epsilon-0.1,epsilon-0.05} --out "$out/tuning.md"
