#!/usr/bin/env bash
# The inspection rule (A5) at the defaults then (50 m headway scale, epsilon 0.15) on the tuning
# seeds 0-2, 2 runs x 250 episodes each, in-process shields: the literal first-by-index
# reading, which did best on the reduced protocol at the 200 m scale but was never tuned,
# against "any" (the default), whose rows are the epsilon 0.15 rows of results/scripts/epsilon.sh
# (the same resolved configuration). One table: results/tuning/inspect/inspect.md.
# Resumable: finished experiments are skipped.
set -euo pipefail
cd "$(dirname "$0")/../.."
source scripts/_venv.sh
out=results/tuning/inspect
for seed in 0 1 2; do
    .venv/bin/python -m client run --arms ddpg+shield \
        --shield-config '{"reviser": {"inspect": "first_index"}}' \
        --out "$out/seed-$seed/first-index" --runs 2 --episodes 250 --seed "$seed" \
        --shield local --workers 2 >/dev/null
done
eps=results/tuning/epsilon
.venv/bin/python -m client compare \
    "$eps"/seed-0/epsilon-0.15 "$out"/seed-0/first-index \
    "$eps"/seed-1/epsilon-0.15 "$out"/seed-1/first-index \
    "$eps"/seed-2/epsilon-0.15 "$out"/seed-2/first-index \
    --out "$out/inspect.md"
