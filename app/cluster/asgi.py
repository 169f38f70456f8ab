"""One HTTP request through an ASGI app in this process: how a shard answers what the ingress
forwards, with the plain service's routes, validation and errors, without a socket."""

from __future__ import annotations

import asyncio
from dataclasses import dataclass
from typing import Any

from starlette.types import ASGIApp, Message


@dataclass(frozen=True)
class Request:
    """What the ingress forwards: method, path, raw query, headers and body."""

    method: str
    path: str
    query: bytes = b""
    headers: tuple[tuple[bytes, bytes], ...] = ()
    body: bytes = b""


@dataclass(frozen=True)
class Reply:
    """The app's answer, whole."""

    status: int
    headers: tuple[tuple[bytes, bytes], ...]
    body: bytes


async def call(app: ASGIApp, request: Request) -> Reply:
    """Run ``request`` through ``app`` and collect its whole response."""
    scope: dict[str, Any] = {
        "type": "http", "asgi": {"version": "3.0"}, "http_version": "1.1",
        "method": request.method, "scheme": "http", "path": request.path,
        "raw_path": request.path.encode(), "query_string": request.query, "root_path": "",
        "headers": list(request.headers), "client": ("127.0.0.1", 0),
        "server": ("127.0.0.1", 80),
    }
    delivered = False
    status, headers, chunks = 500, (), []
    done = asyncio.Event()

    async def receive() -> Message:
        nonlocal delivered
        if not delivered:
            delivered = True
            return {"type": "http.request", "body": request.body, "more_body": False}
        await done.wait()  # the client of a whole request never leaves before the reply
        return {"type": "http.disconnect"}

    async def send(message: Message) -> None:
        nonlocal status, headers
        if message["type"] == "http.response.start":
            status, headers = message["status"], tuple(message.get("headers", ()))
        elif message["type"] == "http.response.body":
            chunks.append(message.get("body", b""))
            if not message.get("more_body", False):
                done.set()

    await app(scope, receive, send)
    done.set()
    return Reply(status, headers, b"".join(chunks))
