#!/usr/bin/env bash
# The risk reviser (docs/risk-reviser.md) against the paper reviser (today's default) with
# DDPG on tuning seeds 4 and 5: 2 runs x 200 episodes per row, one lockstep group each,
# in-process shields. Writes results/tuning/risk-reviser/seed-S/ROW and seed-S.md.
# ROWS="name=overrides ..." replaces the rows (seed 4 ran them all, seed 5 the first two).
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/_venv.sh
rows=${ROWS:-'paper-default={}
risk-t0-m0.001={"reviser":{"method":"risk"},"risk":{"threshold":0.0,"margin":0.001}}
risk-t0-m0={"reviser":{"method":"risk"},"risk":{"threshold":0.0,"margin":0.0}}
risk-t0-m0.005={"reviser":{"method":"risk"},"risk":{"threshold":0.0,"margin":0.005}}
risk-t0.01-m0.005={"reviser":{"method":"risk"},"risk":{"threshold":0.01,"margin":0.005}}
risk-t0.01-m0.005-h16={"reviser":{"method":"risk"},"risk":{"threshold":0.01,"margin":0.005,"horizon":16}}
risk-t0.05-m0.02={"reviser":{"method":"risk"},"risk":{"threshold":0.05,"margin":0.02}}'}
for seed in ${SEEDS:-4 5}; do
    out=results/tuning/risk-reviser/seed-$seed
    dirs=()
    while IFS='=' read -r name config; do
        [ -n "$name" ] || continue
        .venv/bin/python -m client run --arms ddpg+shield --shield-config "$config" \
            --out "$out/$name" --runs 2 --episodes 200 --seed "$seed" --shield local \
            --lockstep --workers 1 >/dev/null
        dirs+=("$out/$name")
    done <<<"$rows"
    .venv/bin/python -m client compare "${dirs[@]}" --blocks --out "$out.md"
done
