#!/usr/bin/env bash
# How fast the paper's protocol trains in each arrangement named in LAYOUTS: each runs
# results/scripts/paper-protocol.sh from episode 1 for SECONDS_EACH seconds (default 180), then stops;
# bench/device_pace.py reads the pace from the records (steps and wall_s of every episode).
# ROUNDS (default 1) repeats the whole list, so that a drift of the machine's speed falls on
# every layout.
#
#   LAYOUTS="NAME:VARIABLES;..." bench/layouts.sh OUT
#
# A layout is "NAME:VARIABLES" with the variables of results/scripts/paper-protocol.sh, for example
# "gpu-ws:LOCKSTEP=1 DEVICE=cuda GROUP=10 TRANSPORT=ws" or, for the shielded arm alone,
# "b10:ARMS=ddpg+shield LOCKSTEP=1 GROUP=10 TRANSPORT=batch". Per layout OUT gets
# NAME.tar.gz (NAME-rK.tar.gz with ROUNDS > 1): its records, its services' logs and the
# protocol's output, protocol.log.
set -uo pipefail
cd "$(dirname "$0")/.." || exit 1
out=$(realpath -m "$1")
seconds=${SECONDS_EACH:-180}
rounds=${ROUNDS:-1}
: "${LAYOUTS:?name the layouts, for example LAYOUTS=\"b10:LOCKSTEP=1 GROUP=10 TRANSPORT=batch\"}"
mkdir -p "$out"
IFS=';' read -ra chosen <<<"$LAYOUTS"
for ((round = 1; round <= rounds; round++)); do
    for layout in "${chosen[@]}"; do
        name=${layout%%:*}
        [ "$rounds" -eq 1 ] || name="$name-r$round"
        work=$(mktemp -d)
        echo "== $name: ${layout#*:} for $seconds s"
        # shellcheck disable=SC2086  # the layout's variables are words
        env ${layout#*:} timeout "$seconds" results/scripts/paper-protocol.sh "$work/$name" \
            >"$work/protocol.log" 2>&1
        echo "stopped after $seconds s (status $?)" >>"$work/protocol.log"
        mv "$work/protocol.log" "$work/$name/"
        tar -czf "$out/$name.tar.gz" -C "$work" "$name"
        tail -3 "$work/$name/protocol.log"
        rm -rf "$work"
    done
done
