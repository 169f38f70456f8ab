"""The shield app plus two floors for ``bench/service.py``: a no-op route and a WebSocket echo.

    python bench/service_app.py PORT
"""

from __future__ import annotations

import sys

import uvicorn
from fastapi import WebSocket, WebSocketDisconnect

from app.api.schemas import ReviseRequest
from app.main import create_app
from app.settings import Settings


def build() -> object:
    api = create_app(Settings())

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


if __name__ == "__main__":
    uvicorn.run(build(), host="127.0.0.1", port=int(sys.argv[1]), log_level="warning",
                access_log=False)
