#!/usr/bin/env bash
# The paper's protocol: 10 runs x 1500 episodes of ddpg and ddpg+shield on the evaluation seeds
# (base seed 1000), CMAP training traces, default shield configuration. Every shielded run asks
# a shield service of its own over WebSocket (a sidecar per controller, in-memory models); all
# 20 runs train in parallel processes, so it wants 16 cores or more.
#
#   results/paper-protocol.sh [OUT]          (default OUT: results/paper-protocol-50m)
#
# results/paper-protocol holds the partial run made when the default normalised the headway by
# 200 m; to continue that one, check out commit 1f428c5 and pass it as OUT.
#
# DEVICE=cuda trains the DDPG learners in lockstep groups of GROUP runs (default 5), each group's
# update a CUDA graph on the GPU (client/agents/ensemble.py), the group's shield requests sent
# together; without it every run trains in its own process on the CPU.
#
# RUNS and EPISODES override the sizes, PORT the first of the services' ports (8300); PYTHON
# names an interpreter that already has the project's packages (otherwise .venv is made as
# scripts/test makes it). Resumable: run it again with the same OUT to continue (records are
# appended per episode).
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-results/paper-protocol-50m}
runs=${RUNS:-10}
episodes=${EPISODES:-1500}
first_port=${PORT:-8300}
device=${DEVICE:-}
group=${GROUP:-5}
if [ -z "${PYTHON:-}" ]; then
    source scripts/_venv.sh
    PYTHON=.venv/bin/python
fi
mkdir -p "$out/services"

services=()
trap 'kill "${services[@]}" 2>/dev/null || true; wait' EXIT  # and wait: no service outlives the run
urls=()
for ((i = 0; i < runs; i++)); do
    port=$((first_port + i))
    "$PYTHON" -m app serve --host 127.0.0.1 --port "$port" >"$out/services/shield-$i.log" 2>&1 &
    services+=($!)
    urls+=("http://127.0.0.1:$port")
done
for ((i = 0; i < runs; i++)); do
    until EFSM_PORT=$((first_port + i)) "$PYTHON" -m app.healthcheck; do
        kill -0 "${services[i]}" 2>/dev/null ||
            { echo "shield service $i did not start; see $out/services/shield-$i.log" >&2; exit 1; }
        sleep 0.2
    done
done

if [ -n "$device" ]; then
    groups=$(((runs + group - 1) / group))
    learning=(--lockstep --lockstep-runs "$group" --device "$device" --workers $((2 * groups)))
    how="lockstep groups of $group runs learning on $device, $((2 * groups)) worker processes"
else
    learning=(--workers $((2 * runs)))
    how="every run in its own process on the CPU, $((2 * runs)) worker processes"
fi
{
    echo "started: $(date -u +%FT%TZ)"
    echo "cpu: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2- | xargs), $(nproc --all) cores"
    if [ "$device" = cuda ]; then
        echo "gpu: $(nvidia-smi --query-gpu=name --format=csv,noheader | head -1)"
    fi
    echo "runs: $runs x $episodes episodes per arm; $how"
} >"$out/machine.txt"
start=$(date +%s)
"$PYTHON" -m client run --arms ddpg,ddpg+shield --runs "$runs" --episodes "$episodes" \
    --seed 1000 --shield "$(IFS=,; echo "${urls[*]}")" --transport ws "${learning[@]}" \
    --out "$out"
echo "wall: $(($(date +%s) - start)) s" >>"$out/machine.txt"
