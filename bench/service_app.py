"""The shield app plus two floors for ``bench/service.py``: a no-op route and a WebSocket echo.

``--timing`` also times every call of ``ModelRegistry.try_step`` (the model's share of a
single request: validation, journal, the e-FSM step) and serves the times at
``GET /bench/timing``, which hands them over and starts afresh (for
``bench/service_split.py``).

    python bench/service_app.py PORT [--timing]
"""

from __future__ import annotations

import sys
import time
from typing import Any

import uvicorn
from fastapi import FastAPI, WebSocket, WebSocketDisconnect

from app.api.schemas import ReviseRequest
from app.main import create_app
from app.service.registry import ModelRegistry
from app.settings import Settings


def build(timing: bool = False) -> FastAPI:
    api = create_app(Settings())
    if timing:
        times = time_model_steps()

        @api.get("/bench/timing")
        def timing_route() -> list[float]:
            """Seconds of every model step since the last call."""
            out = list(times)
            times.clear()
            return out

    @api.post("/bench/noop")
    async def noop(body: ReviseRequest) -> dict[str, bool]:
        """A pydantic body in, a small JSON out."""
        return {"ok": True}

    @api.websocket("/bench/echo")
    async def echo(websocket: WebSocket) -> None:
        await websocket.accept()
        try:
            while True:
                await websocket.send_text(await websocket.receive_text())
        except WebSocketDisconnect:
            return

    return api


def time_model_steps() -> list[float]:
    """Wrap ``ModelRegistry.try_step`` so that each call appends its seconds to the list."""
    times: list[float] = []
    try_step = ModelRegistry.try_step

    def timed(self: ModelRegistry, *args: Any, **kwargs: Any) -> Any:
        start = time.perf_counter()
        try:
            return try_step(self, *args, **kwargs)
        finally:
            times.append(time.perf_counter() - start)

    ModelRegistry.try_step = timed  # type: ignore[method-assign]
    return times


if __name__ == "__main__":
    uvicorn.run(
        build("--timing" in sys.argv),
        host="127.0.0.1",
        port=int(sys.argv[1]),
        log_level="warning",
        access_log=False,
    )
