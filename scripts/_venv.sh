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
    echo "setting up .venv (once per change of pyproject.toml): this project with its service," \
         "client and dev extras, torch 2.13.0 (CPU) among them; a few minutes the first time" >&2
    .venv/bin/python -m pip install --quiet --upgrade pip
    .venv/bin/python -m pip install --quiet --quiet -e ".[service,client,dev]"
    .venv/bin/python -m app warm >&2  # compile the core's kernels into their cache now
    echo "$want" >"$stamp"
    echo ".venv is ready" >&2
fi
