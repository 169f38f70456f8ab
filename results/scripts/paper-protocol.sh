#!/usr/bin/env bash
# The paper's protocol: 10 runs x 1500 episodes of ddpg and ddpg+shield on the evaluation seeds
# (base seed 1000), CMAP training traces, default shield configuration. Every shielded run asks
# a shield service of its own over WebSocket (a sidecar per controller, in-memory models); all
# 20 runs train in parallel processes, so it wants 16 cores or more.
#
#   results/scripts/paper-protocol.sh [OUT]          (default OUT: results/paper-protocol-default)
#
# results/paper-protocol holds the partial run made when the default normalised the headway by
# 200 m; to continue that one, check out commit 1f428c5 and pass it as OUT. Likewise
# results/paper-protocol-50m, made with epsilon 0.3: commit 083199b;
# results/paper-protocol-eps-0.15, made with one-sided revisions off: commit c520107;
# results/paper-protocol-one-sided, made without the knee: commit 7cf2170; and
# results/paper-protocol-knee, made with flags per recognition: commit 2cac6a3.
# results/paper-protocol-entry-rate ran today's default as overrides (SHIELD_CONFIG, below):
# the same overrides regenerate it (results/README.md has the command).
#
# How the runs learn, and how they reach the shield:
#
#   (nothing)       every run in its own process on the CPU, every shielded run asking a
#                   service of its own over WebSocket (a sidecar per controller): 16 cores or more
#   LOCKSTEP=1      the runs of an arm train in lockstep groups (client/agents/ensemble.py):
#                   GROUP runs per shielded group (default 5; with DEVICE=cuda all the runs),
#                   DDPG_GROUP per group of DDPG alone (default GROUP); DEVICE=cuda puts the
#                   groups' updates on the GPU. On the device's H200 machine one group of 10
#                   per arm trained 2.9x (DDPG alone) and 1.1x (shielded) as fast as a process
#                   per run, and groups of 2 were slower than both (BENCHMARKS.md)
#   TRANSPORT=batch SERVICES services (default 1) for the shielded runs, run i on service
#                   i mod SERVICES; a lockstep group's round of steps is one request of the
#                   batch route per service, all in flight at once (default ws: a service
#                   per run, as above)
#
#   STOP_AFTER=M   with LOCKSTEP=1: after M minutes every group saves its state in OUT/checkpoints
#                  and stops; the same command goes on from there (gzipped records of runs
#                  not finished are unpacked to go on). Groups also save every 10 minutes, so
#                  a crash loses at most that much
#   ARMS="..."     the arms to run (default "ddpg ddpg+shield")
#   SHIELD_CONFIG=JSON  overrides of the default shield configuration (client run
#                  --shield-config), e.g. '{"reviser": {"flags": "sticky"}}'; give OUT a
#                  folder of its own
#   LOG_LEVEL=L    the services' log level (default warning; info logs every request)
#   UPDATE_FIRST=1 DDPG updates before each step, while the shield service answers (client run
#                  --update-first): faster against a service, but not the usual order's
#                  results; give OUT a folder of its own
#
# The two arms run as two `client run` commands side by side, so their groups can differ. On
# 2 cores, LOCKSTEP=1 GROUP=10 TRANSPORT=batch: two shielded groups of 5 overlap one group's
# learning with the other's wait for answers, but in two minutes of each here the shielded
# runs stepped no faster (about 9.5 ms a step) and DDPG alone beside them 1.5 times slower;
# the cores are busy either way, and a batched update of 5 learners costs more than half of
# one of 10. The shielded arm alone, too, stepped as fast in one group with one service as in
# two groups of 5 or with SERVICES=2 (bench/layouts.sh, BENCHMARKS.md).
set -euo pipefail
cd "$(dirname "$0")/../.."
out=${1:-results/paper-protocol-default}
runs=${RUNS:-10}
episodes=${EPISODES:-1500}
first_port=${PORT:-8300}
if [ -z "${PYTHON:-}" ]; then
    source scripts/_venv.sh
    PYTHON=.venv/bin/python
fi
lockstep=${LOCKSTEP:-}
device=${DEVICE:-cpu}
[ "$device" = cuda ] && group=${GROUP:-$runs} || group=${GROUP:-5}
ddpg_group=${DDPG_GROUP:-$group}
transport=${TRANSPORT:-ws}
case "$transport" in
    ws) services=$runs ;;
    batch) services=${SERVICES:-1} ;;
    *) echo "TRANSPORT: ws or batch, not $transport" >&2; exit 2 ;;
esac
mkdir -p "$out/services"

pids=()
trap 'kill "${pids[@]}" 2>/dev/null || true; wait' EXIT  # and wait: no service outlives the run
urls=()
for ((i = 0; i < services; i++)); do
    port=$((first_port + i))
    "$PYTHON" -m app serve --host 127.0.0.1 --port "$port" --log-level "${LOG_LEVEL:-warning}" \
        >>"$out/services/shield-$i.log" 2>&1 &
    pids+=($!)
    urls+=("http://127.0.0.1:$port")
done
for ((i = 0; i < services; i++)); do
    until EFSM_PORT=$((first_port + i)) "$PYTHON" -m app.healthcheck; do
        kill -0 "${pids[i]}" 2>/dev/null ||
            { echo "shield service $i did not start; see $out/services/shield-$i.log" >&2; exit 1; }
        sleep 0.2
    done
done

# arm_options GROUP: the learning options of an arm's command, its lockstep groups GROUP runs
arm_options() {
    if [ -n "$lockstep" ]; then
        echo "--lockstep --lockstep-runs $1 --device $device --workers $(((runs + $1 - 1) / $1))"
        [ -z "${STOP_AFTER:-}" ] || echo "--stop-after $STOP_AFTER"
    else
        echo "--workers $runs"
    fi
}
if [ -n "$lockstep" ]; then
    how="lockstep on $device: ddpg in groups of $ddpg_group runs, ddpg+shield in groups of $group"
else
    how="every run in its own process on the CPU"
fi
{  # appended: a run that goes on from checkpoints adds its own lines
    echo "started: $(date -u +%FT%TZ) (commit $(git rev-parse --short HEAD 2>/dev/null || echo unknown))"
    echo "cpu: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2- | xargs), $(nproc --all) cores"
    if [ "$device" = cuda ]; then
        echo "gpu: $(nvidia-smi --query-gpu=name --format=csv,noheader | head -1)"
    fi
    echo "runs: $runs x $episodes episodes per arm; $how; $services shield service(s), $transport"
    echo "shield overrides: ${SHIELD_CONFIG:-{\}}"
    [ -z "${UPDATE_FIRST:-}" ] || echo "ddpg: update first"
} >>"$out/machine.txt"
start=$(date +%s)
arms=()
for arm in ${ARMS:-ddpg ddpg+shield}; do
    [ "$arm" = ddpg ] && size=$ddpg_group || size=$group
    # shellcheck disable=SC2046  # the options are words
    "$PYTHON" -m client run --arms "$arm" --runs "$runs" --episodes "$episodes" --seed 1000 \
        --shield "$(IFS=,; echo "${urls[*]}")" --transport "$transport" \
        --shield-config "${SHIELD_CONFIG:-{\}}" $(arm_options "$size") \
        ${UPDATE_FIRST:+--update-first} --out "$out" &
    arms+=($!)
    pids+=($!)  # stopping the script stops the arms too
done
status=0
for pid in "${arms[@]}"; do wait "$pid" || status=1; done
echo "wall: $(($(date +%s) - start)) s" >>"$out/machine.txt"
exit $status
