#!/usr/bin/env bash
# The risk reviser (docs/lab/risk-reviser.md) against the paper reviser with DDPG, 2 runs per row,
# one lockstep group each, in-process shields.
#   results/scripts/risk-reviser.sh          tuning seeds 4, 5 and 6, 200 episodes a run:
#                                    results/tuning/risk-reviser/seed-S/ROW, seed-S-activation.md
#   EVAL=1 results/scripts/risk-reviser.sh   the evaluation seeds (base 1000), 300 episodes a run:
#                                    results/reduced/risk-reviser/ROW, risk-reviser.md
# The rows: the paper reviser as ShieldConfig.paper() has it (the default until commit
# 5c3ff1b), the risk reviser activated after 50 episodes (today's default), the same from the
# first episode (tried and not kept; on seed 4 also the paper reviser from the first) and
# with a horizon of 24 steps.
# ROWS="name=overrides ..." (one per line) replaces them. The other rows under
# results/tuning/risk-reviser (risk-t*) counted only tried actions in the safest
# continuation: they regenerate at commit 1202fea with their folder's overrides (in each
# record's header), risk-t0-m0.001 of seed 5 with '{"reviser":{"method":"risk"}}' there.
set -euo pipefail
cd "$(dirname "$0")/../.."
source scripts/_venv.sh
rows=${ROWS:-'paper-default={"reviser":{"method":"paper","activate_after_episodes":50}}
risk-default={"reviser":{"method":"risk","activate_after_episodes":50}}
risk-act0={"reviser":{"activate_after_episodes":0}}
risk-h24={"risk":{"horizon":24}}'}
if [ -n "${EVAL:-}" ]; then
    seeds=1000 episodes=300
else
    seeds="4 5 6" episodes=200
fi
for seed in $seeds; do
    if [ -n "${EVAL:-}" ]; then
        out=results/reduced/risk-reviser table=results/reduced/risk-reviser.md
    else
        out=results/tuning/risk-reviser/seed-$seed table=$out-activation.md
    fi
    dirs=()
    while IFS='=' read -r name config; do
        [ -n "$name" ] || continue
        .venv/bin/python -m client run --arms ddpg+shield --shield-config "$config" \
            --out "$out/$name" --runs 2 --episodes "$episodes" --seed "$seed" \
            --shield local --lockstep --workers 1 >/dev/null
        dirs+=("$out/$name")
    done <<<"$rows"
    .venv/bin/python -m client compare "${dirs[@]}" --blocks --out "$table"
done
