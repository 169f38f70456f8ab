#!/usr/bin/env bash
# DDPG alone against today's default shield on the evaluation seeds with twice the runs of the
# reduced protocol (4 runs x 300 episodes per arm, base seed 1000, in-process shields), both
# on one machine: two runs a row were found too few to rank settings (results/README.md, "The
# clustering radius"). Runs 0 and 1 are those of the reduced protocol's rows (seeds are
# spawned per run index), recomputed here. One table: results/reduced/four-runs/four-runs.md.
# Resumable: finished experiments are skipped.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/_venv.sh
out=results/reduced/four-runs
for arm in ddpg ddpg+shield; do
    .venv/bin/python -m client run --arms "$arm" --out "$out/${arm/+/-}" --runs 4 \
        --episodes 300 --seed 1000 --shield local --workers 2 >/dev/null
done
.venv/bin/python -m client compare "$out"/{ddpg,ddpg-shield} --out "$out/four-runs.md"
