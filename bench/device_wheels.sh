#!/usr/bin/env bash
# The wheels a device call needs besides that machine's own torch and numpy: the service's and
# the client's packages at the versions of this checkout's .venv, for its Python 3.12, into
# .whl (ignored; name it in the call's carry). The call then begins with
#   python3 -m pip install -q --no-index --no-deps --target /tmp/site .whl/*.whl &&
#   export PYTHONPATH=/tmp/site:$PWD
set -euo pipefail
cd "$(dirname "$0")/.."
grep -qx '/.whl/' .git/info/exclude 2>/dev/null || echo /.whl/ >>.git/info/exclude
names="fastapi starlette pydantic pydantic_core pydantic-settings python-dotenv annotated-types
annotated-doc typing-inspection typing_extensions opentelemetry-api uvicorn websockets httptools
websocket-client gymnasium farama-notifications typer click"
pins=$(.venv/bin/python -m pip freeze 2>/dev/null | tr '[:upper:]' '[:lower:]' | tr _ -)
wanted=()
for name in $names; do
    key=$(echo "$name" | tr '[:upper:]' '[:lower:]' | tr _ -)
    wanted+=("$(echo "$pins" | grep -m1 "^$key==")")
done
rm -rf .whl
python3 -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 \
    --implementation cp --platform manylinux_2_28_x86_64 --platform manylinux_2_17_x86_64 \
    --platform manylinux2014_x86_64 --platform manylinux1_x86_64 -d .whl "${wanted[@]}"
ls .whl
