#!/usr/bin/env bash
# The reduced protocol of issue #44 on the evaluation seeds (base seed 1000): the risk reviser
# (today's default) against the paper's reviser as it was the default (ShieldConfig.paper())
# and the paper's literal reading (ShieldConfig.paper_literal()), DDPG, 4 runs x 600 episodes
# per arm, one lockstep group each, in-process shields, two arms at a time. Resumable: run it
# again to go on with an interrupted arm. Records and the table in results/reduced/default-switch.
set -euo pipefail
cd "$(dirname "$0")/../.."
source scripts/_venv.sh
out=results/reduced/default-switch
preset() {
    .venv/bin/python -c "import json; from app.core import ShieldConfig
print(json.dumps(ShieldConfig.$1().to_dict()))"
}
export out
arm() {  # NAME OVERRIDES
    .venv/bin/python -m client run --arms ddpg+shield --shield-config "$2" --out "$out/$1" \
        --runs 4 --episodes 600 --seed 1000 --shield local --lockstep --workers 1 >/dev/null
    echo "done: $1"
}
export -f arm
printf '%s\n' "risk-default	{}" "paper	$(preset paper)" "paper-literal	$(preset paper_literal)" |
    xargs -P "${JOBS:-2}" -d '\n' -I{} bash -c 'IFS=$'"'\t'"' read -r n c <<<"$1"; arm "$n" "$c"' _ {}
.venv/bin/python -m client compare "$out"/{risk-default,paper,paper-literal} --blocks \
    --out results/reduced/default-switch.md
