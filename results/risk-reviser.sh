#!/usr/bin/env bash
# The risk reviser (docs/risk-reviser.md) against the paper reviser (today's default) with
# DDPG on tuning seeds 4 and 5: 2 runs x 200 episodes per row, one lockstep group each,
# in-process shields. Writes results/tuning/risk-reviser/seed-S/ROW and seed-S.md.
# ROWS="name=overrides ..." (one per line) replaces the rows. The other rows under
# results/tuning/risk-reviser (risk-t*) counted only tried actions in the safest
# continuation: they regenerate at commit 1202fea with their folder's overrides (in each
# record's header), risk-t0-m0.001 of seed 5 with '{"reviser":{"method":"risk"}}' there.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/_venv.sh
rows=${ROWS:-'paper-default={}
risk-default={"reviser":{"method":"risk"}}'}
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
    .venv/bin/python -m client compare "${dirs[@]}" --blocks --out "$out-default.md"
done
