#!/usr/bin/env bash
# What one call of the device tool's GPU machine runs (16 cores and one GPU; 15 minutes of
# device time a session, so everything in one call):
#
#   1. the lockstep tests, whose CUDA cases skip everywhere else (the graph-captured update
#      must learn what separate runs learn);
#   2. bench/learner.py: a training step of 1, 5 and 10 learners, separate, batched on the
#      CPU and batched as a CUDA graph; bench/rounding_drift.py: how far the CUDA ensemble
#      drifts from separate runs;
#   3. bench/layouts.sh: the paper's protocol (results/scripts/paper-protocol.sh) in each
#      arrangement named in LAYOUTS, from episode 1 for SECONDS_EACH seconds each (default
#      180), then stopped: how fast each arrangement trains on this machine, from the records
#      (steps and wall_s of every episode).
#
#   bench/device.sh OUT           (OUT: a new folder; PYTHON defaults to python3)
#
# That machine has torch and numpy but not the service's and client's other packages:
# bench/device_wheels.sh fetches them here as wheels, and its header says how the call
# installs them. bench/device_pace.py turns the layouts' archives into a table.
#
# A layout is "NAME:VARIABLES" (bench/layouts.sh), for example
# "gpu-ws:LOCKSTEP=1 DEVICE=cuda GROUP=10 TRANSPORT=ws". What it writes under OUT: machine.txt,
# tests.log, learner.json, learner.md, rounding-drift.md, and per layout NAME.tar.gz (its
# records, its services' logs and the protocol's output, protocol.log): at most 8 files come
# back from the machine, so at most 3 layouts.
set -uo pipefail
cd "$(dirname "$0")/.." || exit 1
out=$(realpath -m "$1")
python=${PYTHON:-python3}
seconds=${SECONDS_EACH:-180}
layouts=${LAYOUTS:-"gpu-ws:LOCKSTEP=1 DEVICE=cuda GROUP=10 TRANSPORT=ws"}
mkdir -p "$out"
export PYTHONUNBUFFERED=1
{
    echo "cpu: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2- | xargs), $(nproc --all) cores"
    nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader 2>&1 |
        sed 's/^/gpu: /'
    "$python" -c 'import sys, numpy, torch; print("versions: python", sys.version.split()[0],
        "numpy", numpy.__version__, "torch", torch.__version__)'
    # the machine's copy of the history may predate the session's commits: say what differs
    echo "commit: $(git rev-parse --short HEAD 2>/dev/null || echo unknown)," \
        "$(git status --porcelain 2>/dev/null | wc -l) paths changed or new in the working tree"
} >"$out/machine.txt"
cat "$out/machine.txt"

"$python" -m pytest -p no:cacheprovider -q -rs tests/client/test_ensemble.py 2>&1 |
    tee "$out/tests.log"
"$python" bench/learner.py --rounds 3 --steps 200 --json "$out/learner.json" 2>&1 |
    tee "$out/learner.md"
"$python" bench/rounding_drift.py 2>&1 | tee "$out/rounding-drift.md"

SECONDS_EACH=$seconds LAYOUTS=$layouts PYTHON=$python bench/layouts.sh "$out"
