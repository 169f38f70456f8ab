"""The dependency rule: app.core <- app.service <- app.api <- app.main; app never imports
client; nothing of the service imports torch (its container has none), nor does the Python
client (its extra has none); only the Ray deployment imports Ray (an optional extra)."""

from __future__ import annotations

import subprocess
import sys

import pytest


def imported_after(module: str) -> set[str]:
    code = f"import sys, {module}; print('\\n'.join(sorted(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True)
    return set(out.stdout.split())


def top(modules: set[str]) -> set[str]:
    return {name.split(".")[0] for name in modules}


def test_core_needs_numpy_and_numba_alone() -> None:
    loaded = imported_after("app.core")
    assert not top(loaded) & {"fastapi", "pydantic", "httpx", "torch", "starlette", "client"}
    assert not {m for m in loaded if m.startswith(("app.service", "app.api"))}


def test_service_layer_knows_nothing_of_http() -> None:
    loaded = imported_after("app.service.registry")
    assert not top(loaded) & {"fastapi", "starlette", "torch", "client"}
    assert not {m for m in loaded if m.startswith("app.api")}


@pytest.mark.parametrize("module", ["app.main", "app.__main__", "app.cluster.ray_serve"])
def test_the_service_imports_neither_torch_nor_the_client(module: str) -> None:
    assert not top(imported_after(module)) & {"torch", "client"}


@pytest.mark.parametrize("module", ["client.shield", "client.sim"])
def test_the_python_client_needs_no_torch(module: str) -> None:
    """What the 'client' extra installs (httpx, websocket-client, gymnasium) is enough for the
    clients, the WebSocket session, the wrappers and the simulator: torch, blocked here, is
    never imported, nor is anything of the 'experiment' or 'service' extras."""
    code = (
        f"import sys; sys.modules['torch'] = None; import {module}; "
        "print('\\n'.join(sorted(sys.modules)))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    loaded = top(set(out.stdout.split()))
    assert not loaded & {"typer", "tqdm", "matplotlib", "fastapi", "uvicorn", "pydantic"}


def test_ray_is_loaded_only_by_the_ray_deployment() -> None:
    assert "ray" not in top(imported_after("app.__main__"))
    assert "ray" not in top(imported_after("app.cluster.ingress"))
