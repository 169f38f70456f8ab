#!/usr/bin/env bash
# The diagnosis of results/README.md, on a tuning seed (0): one shielded DDPG run of 150
# episodes with sticky flags (the spec's recommendation) and one with count-based flags (the
# default), each against the shield service over a WebSocket; then every state of the
# learned model, from GET /models/{name}, into results/diagnosis/<flags>/states.md.
set -euo pipefail
cd "$(dirname "$0")/../.."
source scripts/_venv.sh
port=${PORT:-8765}
.venv/bin/python -m app serve --port "$port" --log-level warning &
server=$!
trap 'kill $server' EXIT
until EFSM_PORT=$port .venv/bin/python -m app.healthcheck; do sleep 0.2; done
for flags in sticky rate; do
    out=results/diagnosis/$flags
    .venv/bin/python -m client run --arms ddpg+shield --runs 1 --episodes 150 --seed 0 \
        --shield "http://127.0.0.1:$port" --transport ws --out "$out" \
        --shield-config "{\"reviser\": {\"flags\": \"$flags\"}}" >/dev/null
    .venv/bin/python results/scripts/states_table.py "http://127.0.0.1:$port/models/exp-ddpg-shield-0" \
        >"$out/states.md"
    cat "$out/table.md" "$out/states.md"
done
