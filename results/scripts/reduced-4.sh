#!/usr/bin/env bash
# DDPG alone against the shield on the evaluation seeds with twice the runs of the reduced
# protocol (4 runs x 300 episodes per arm, base seed 1000, in-process shields), all on one
# machine: two runs a row were found too few to rank settings (results/README.md, "The
# clustering radius"). Runs 0 and 1 are those of the reduced protocol's rows (seeds are
# spawned per run index), recomputed here. Rows: DDPG alone; the shield with one-sided
# revisions off (ddpg-shield, recorded with `{}` while off was the default: commit c520107,
# the last such, regenerates it; later code refuses to extend it); and one-sided revisions
# (ddpg-shield-one-sided, the default then, asked for explicitly); and the double knee
# (ddpg-shield-knee-double, tuned by results/scripts/knee-double.sh on seeds 4 and 5; recorded with
# flags per recognition, the default until commit 2cac6a3, which regenerates it). One table:
# results/reduced/four-runs/four-runs.md. Resumable: finished experiments are skipped.
set -euo pipefail
cd "$(dirname "$0")/../.."
source scripts/_venv.sh
out=results/reduced/four-runs
run() {  # run OUT ARM [OVERRIDES]
    .venv/bin/python -m client run --arms "$2" --out "$out/$1" --runs 4 --episodes 300 \
        --seed 1000 --shield local --workers 2 --shield-config "${3:-{\}}" >/dev/null
}
run ddpg ddpg
[[ -d $out/ddpg-shield ]] || run ddpg-shield ddpg+shield '{"reviser": {"one_sided": false}}'
# recorded without the knee, the default until commit 7cf2170, which regenerates it; later
# code refuses to extend it
[[ -d $out/ddpg-shield-one-sided ]] || run ddpg-shield-one-sided ddpg+shield \
    '{"reviser": {"one_sided": true}, "observation": {"knee": []}}'
run ddpg-shield-knee-double ddpg+shield \
    '{"observation": {"knee": [0.0, 20.0, 0.0], "knee_shape": "double"}}'
.venv/bin/python -m client compare \
    "$out"/{ddpg,ddpg-shield,ddpg-shield-one-sided,ddpg-shield-knee-double} \
    --out "$out/four-runs.md"
