"""One HTTP request through an ASGI app in this process: how a shard answers what the ingress
forwards, with the plain service's routes, validation and errors, without a socket. A whole
answer (:func:`call`), or one that streams (:func:`stream`: the live event feed)."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
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


def _scope(request: Request) -> dict[str, Any]:
    return {
        "type": "http",
        "asgi": {"version": "3.0"},
        "http_version": "1.1",
        "method": request.method,
        "scheme": "http",
        "path": request.path,
        "raw_path": request.path.encode(),
        "query_string": request.query,
        "root_path": "",
        "headers": list(request.headers),
        "client": ("127.0.0.1", 0),
        "server": ("127.0.0.1", 80),
    }


async def call(app: ASGIApp, request: Request) -> Reply:
    """Run ``request`` through ``app`` and collect its whole response."""
    scope = _scope(request)
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


async def stream(app: ASGIApp, request: Request) -> AsyncIterator[Reply | bytes]:
    """Run ``request`` through ``app`` and pass its response on as it comes: first its status
    and headers (a :class:`Reply` without a body), then each piece of the body. When the
    reader stops, the app is told that the client left and is stopped."""
    messages: asyncio.Queue[Message | None] = asyncio.Queue()
    left = asyncio.Event()
    delivered = False

    async def receive() -> Message:
        nonlocal delivered
        if not delivered:
            delivered = True
            return {"type": "http.request", "body": request.body, "more_body": False}
        await left.wait()
        return {"type": "http.disconnect"}

    async def run() -> None:
        try:
            await app(_scope(request), receive, messages.put)
        finally:
            messages.put_nowait(None)

    task = asyncio.create_task(run())
    try:
        while (message := await messages.get()) is not None:
            if message["type"] == "http.response.start":
                yield Reply(message["status"], tuple(message.get("headers", ())), b"")
            elif message["type"] == "http.response.body":
                if message.get("body"):
                    yield message["body"]
                if not message.get("more_body", False):
                    break
    finally:
        left.set()
        task.cancel()
