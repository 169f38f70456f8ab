#!/usr/bin/env bash
# Step traces of shielded DDPG runs (`run --trace`, tuning seeds only) and what they say
# (`python -m client trace` into results/diagnosis/trace-<name>/trace.md):
#   headway-200, headway-50: one run of 150 episodes on seed 0 with the headway normalised by
#     200 m (the spec's scale, the default until this diagnosis) and by 50 m (the default since);
#   seed-1-headway-50: both runs of seed 1 at 50 m, 250 episodes, where one run never revised.
set -euo pipefail
cd "$(dirname "$0")/../.."
source scripts/_venv.sh
while IFS=';' read -r name seed runs episodes overrides; do
    out=results/diagnosis/trace-$name
    .venv/bin/python -m client run --arms ddpg+shield --runs "$runs" --episodes "$episodes" \
        --seed "$seed" --shield local --trace --out "$out" --shield-config "$overrides" \
        >/dev/null
    .venv/bin/python -m client trace "$out" >/dev/null
done <<'JOBS'
headway-200;0;1;150;{"observation": {"high": [32.0, 200.0, 32.0]}}
headway-50;0;1;150;{"observation": {"high": [32.0, 50.0, 32.0]}}
seed-1-headway-50;1;2;250;{"observation": {"high": [32.0, 50.0, 32.0]}}
JOBS
