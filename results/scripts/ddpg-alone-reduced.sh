#!/usr/bin/env bash
# DDPG alone in the reduced protocol on the evaluation seeds (base seed 1000, 4 runs x 600
# episodes, one lockstep group, the paper's reward): the controller-alone row beside the
# shields of results/reduced/default-switch.md. Resumable: run it again to go on. Records and
# the table in results/reduced/ddpg-alone.
set -euo pipefail
cd "$(dirname "$0")/../.."
source scripts/_venv.sh
.venv/bin/python -m client run --arms ddpg --runs 4 --episodes 600 --seed 1000 --shield local \
    --lockstep --workers 1 --out results/reduced/ddpg-alone >/dev/null
.venv/bin/python -m client compare results/reduced/ddpg-alone \
    results/reduced/default-switch/{risk-default,paper} --blocks --out results/reduced/ddpg-alone.md
