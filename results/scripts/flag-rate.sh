#!/usr/bin/env bash
# Do count-based flags lift as the controller learns? In the paper's protocol with today's
# default the shielded runs kept colliding late (about 12% of episodes after episode 700) while
# the shield revised 3-6 times an episode, and the models where the run stopped had most
# collisions recognised in states no longer flagged (states_table.py): a state is flagged
# while its failures make up at least flag_min_rate (0.002) of its recognitions, and a state
# of close following collects recognitions far faster than crashes. Tuning seed 4 (never the
# evaluation seeds), 4 runs x 600 episodes per row in one lockstep group, in-process shields:
# the default, a rate four times lower (0.0005), and sticky flags (the spec's recommendation,
# never lifted). One table, results/tuning/flag-rate/flag-rate.md, and the states of every
# model at the end, <row>/states.md. Resumable. SEED=5 repeats it on another tuning seed, into
# results/tuning/flag-rate-seed-5.
set -euo pipefail
cd "$(dirname "$0")/../.."
source scripts/_venv.sh
seed=${SEED:-4}
out=results/tuning/flag-rate
if [[ $seed != 4 ]]; then out+="-seed-$seed"; fi
rows=("default;{}" "rate-0.0005;{\"reviser\": {\"flag_min_rate\": 0.0005}}"
      "sticky;{\"reviser\": {\"flags\": \"sticky\"}}")
pids=()
for row in "${rows[@]}"; do
    name=${row%%;*}
    .venv/bin/python -m client run --arms ddpg+shield --shield-config "${row#*;}" \
        --out "$out/$name" --runs 4 --episodes 600 --seed "$seed" --shield local --lockstep \
        --workers 1 >/dev/null &
    pids+=($!)
done
for pid in "${pids[@]}"; do wait "$pid"; done
.venv/bin/python -m client compare "$out"/{default,rate-0.0005,sticky} --out "$out/flag-rate.md"
for row in "${rows[@]}"; do  # every model at the end (client run keeps them in <row>/models)
    .venv/bin/python results/scripts/states_table.py "$out/${row%%;*}" >"$out/${row%%;*}/states.md"
done
