"""Plain ASGI middleware: the request size limit and the request metrics."""

from __future__ import annotations

import json
import time
from typing import Any

from prometheus_client import Counter, Histogram
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from app.api.errors import error_body


class BodyLimit:
    """Answer 413 to a body larger than the limit, declared or streamed.

    Snapshots uploaded with PUT have their own, larger limit.
    """

    def __init__(self, app: ASGIApp, limit: int, snapshot_limit: int) -> None:
        self.app = app
        self.limit = limit
        self.snapshot_limit = snapshot_limit

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        limit = self.snapshot_limit if scope["method"] == "PUT" else self.limit
        declared = dict(scope["headers"]).get(b"content-length")
        if declared is not None and declared.isdigit() and int(declared) > limit:
            await self._refuse(send, limit)
            return
        seen = 0
        refused = answered = False

        async def limited() -> Message:
            nonlocal seen, refused
            message = await receive()
            if message["type"] == "http.request":
                seen += len(message.get("body", b""))
                if seen > limit:
                    refused = True
                    raise _TooLarge
            return message

        async def guarded(message: Message) -> None:
            nonlocal answered
            if refused:  # whatever the app makes of the interrupted body, the answer is 413
                if not answered:
                    answered = True
                    await self._refuse(send, limit)
                return
            await send(message)

        try:
            await self.app(scope, limited, guarded)
        except _TooLarge:
            if not answered:
                await self._refuse(send, limit)

    async def _refuse(self, send: Send, limit: int) -> None:
        body = json.dumps(error_body("too_large", f"request body over {limit} bytes"))
        await send(
            {
                "type": "http.response.start",
                "status": 413,
                "headers": [(b"content-type", b"application/json")],
            }
        )
        await send({"type": "http.response.body", "body": body.encode()})


class _TooLarge(Exception):
    pass


class Metrics:
    """Requests and latency by route template, method and status."""

    def __init__(self, app: ASGIApp, requests: Counter, latency: Histogram) -> None:
        self.app = app
        self.requests = requests
        self.latency = latency

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        start = time.perf_counter()
        status: dict[str, Any] = {"code": 500}

        async def record(message: Message) -> None:
            if message["type"] == "http.response.start":
                status["code"] = message["status"]
            await send(message)

        try:
            await self.app(scope, receive, record)
        finally:
            route = scope.get("route")
            path = getattr(route, "path", "unmatched")
            self.requests.labels(path, scope["method"], str(status["code"])).inc()
            self.latency.labels(path).observe(time.perf_counter() - start)
