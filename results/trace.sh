#!/usr/bin/env bash
# Where the shield revises and whether it sees each failure coming, on a tuning seed (0): one
# shielded DDPG run of 150 episodes with every decision traced (`run --trace`), with the
# headway normalised by 200 m (the spec's scale, the default until this diagnosis) and by 50 m
# (the default since); then `python -m client trace` into
# results/diagnosis/trace-<name>/trace.md.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/_venv.sh
while IFS=';' read -r name overrides; do
    out=results/diagnosis/trace-$name
    .venv/bin/python -m client run --arms ddpg+shield --runs 1 --episodes 150 --seed 0 \
        --shield local --trace --out "$out" --shield-config "$overrides" >/dev/null
    .venv/bin/python -m client trace "$out" >/dev/null
done <<'JOBS'
headway-200;{"observation": {"high": [32.0, 200.0, 32.0]}}
headway-50;{"observation": {"high": [32.0, 50.0, 32.0]}}
JOBS
