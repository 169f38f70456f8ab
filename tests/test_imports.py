"""The dependency rule: the core needs numpy alone, and the service never imports torch."""

from __future__ import annotations

import subprocess
import sys


def imported_after(module: str) -> set[str]:
    code = f"import sys, {module}; print('\\n'.join(sorted(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True)
    return {name.split(".")[0] for name in out.stdout.split()}


def test_core_imports_neither_web_nor_torch() -> None:
    loaded = imported_after("app.core")
    assert not loaded & {"fastapi", "pydantic", "httpx", "torch", "starlette", "client"}
