# Sourced by scripts/test and scripts/demo: make .venv and install the project into it, once
# per change of pyproject.toml. torch is pinned to 2.13.0 (the CPU build).
cd "$(dirname "${BASH_SOURCE[0]}")/.."
python=${PYTHON:-python3}
stamp=.venv/.installed
want=$(sha256sum pyproject.toml | cut -d' ' -f1)
if [ ! -x .venv/bin/python ]; then
    "$python" -m venv .venv
fi
if [ "$(cat "$stamp" 2>/dev/null)" != "$want" ]; then
    echo "setting up .venv (once per change of pyproject.toml), in three steps:" >&2
    echo "[1/3] upgrading pip" >&2
    .venv/bin/python -m pip install --quiet --upgrade pip
    echo "[2/3] installing this project with its service, client, experiment and dev extras" \
         "(torch 2.13.0, CPU build, among them): a minute or two the first time" >&2
    .venv/bin/python -m pip install --quiet -e ".[service,client,experiment,dev]"
    echo "[3/3] compiling the core's kernels into their cache: about a minute the first time" \
         "(40-70 s on 2 cores), a second later" >&2
    .venv/bin/python -m app warm >&2
    echo "$want" >"$stamp"
    echo ".venv is ready" >&2
fi
