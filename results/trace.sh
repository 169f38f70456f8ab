#!/usr/bin/env bash
# Where the shield revises and whether it sees each failure coming, on a tuning seed (0): one
# shielded DDPG run of 150 episodes with every decision traced (`run --trace`), with the
# default observation scale (headway / 200 m) and with the headway scaled by 50 m; then
# `python -m client trace` into results/diagnosis/trace-<name>/trace.md.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/_venv.sh
while IFS=';' read -r name overrides; do
    out=results/diagnosis/trace-$name
    .venv/bin/python -m client run --arms ddpg+shield --runs 1 --episodes 150 --seed 0 \
        --shield local --trace --out "$out" --shield-config "$overrides" >/dev/null
    .venv/bin/python -m client trace "$out" >/dev/null
done <<'JOBS'
default;{}
headway-50;{"observation": {"high": [32.0, 50.0, 32.0]}}
JOBS
