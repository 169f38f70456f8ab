"""The ingress of a sharded service: the plain service's HTTP and WebSocket contract, each
request handed to the shard that owns its model.

A request about one model (``/models/{name}/...``, or ``/revise``, ``/model`` and ``/ws`` for
'default') goes to the model's owner (:class:`~app.cluster.placement.Placement`), so a model has
exactly one writer and its steps keep their order. ``GET /models``, ``/readyz`` and
``/metrics`` ask every shard. Two routes are the cluster's own: ``GET /shards`` (where each
shard runs, what it holds) and ``POST /shards/move`` (a model to another shard: its steps wait,
it is snapshotted, restored on the target and deleted from the source, and its steps resume
there). Shards are reached through ``call(shard, method, *args)``, a coroutine: Ray Serve's
handles in :mod:`app.cluster.ray_serve`, the objects themselves in tests.
"""

from __future__ import annotations

import asyncio
import json
import logging
from collections import Counter
from collections.abc import AsyncIterator, Awaitable, Callable
from contextlib import AsyncExitStack, asynccontextmanager
from typing import Any

from fastapi import FastAPI, Request, WebSocket
from fastapi.responses import JSONResponse, Response
from pydantic import BaseModel, Field

import app
from app.api import errors
from app.api.auth import given_token, token_ok
from app.api.deps import check_token
from app.api.errors import POLICY_VIOLATION, STATUS, TooLarge, error_body
from app.api.routes.revise import NamePath
from app.api.routes.stream import refuse, serve_frames
from app.api.schemas import ModelName
from app.cluster import asgi
from app.cluster.placement import Placement, placement_path
from app.core import ShieldError
from app.service.registry import DEFAULT_MODEL
from app.settings import Settings

log = logging.getLogger("app.cluster")

ShardCall = Callable[..., Awaitable[Any]]
"""``call(shard, method, *args)``: run a :class:`~app.cluster.shard.ShardServer` method."""

METHODS = ["GET", "POST", "PUT", "DELETE", "PATCH", "HEAD", "OPTIONS"]


class ShardUnavailable(ShieldError):
    """The shard that owns the model did not answer (it died and restarts from its files)."""

    code = "shard_unavailable"


class SeveralShards(ShieldError):
    """A batch across models names models on different shards."""

    code = "models_on_several_shards"


class UnknownShard(ShieldError):
    """No shard has this index."""

    code = "unknown_shard"


STATUS.update({ShardUnavailable: 503, SeveralShards: 422, UnknownShard: 422})


class MoveRequest(BaseModel):
    """Move ``model`` to shard ``to``."""

    model: ModelName
    to: int = Field(ge=0, description="Index of the target shard.")


class Gates:
    """Per model: the requests in flight, and a move that waits for them and holds new ones."""

    def __init__(self) -> None:
        self._changed = asyncio.Condition()
        self._busy: Counter[str] = Counter()
        self._moving: set[str] = set()

    @asynccontextmanager
    async def use(self, name: str) -> AsyncIterator[None]:
        """Hold ``name`` where it is while a request about it runs."""
        async with self._changed:
            await self._changed.wait_for(lambda: name not in self._moving)
            self._busy[name] += 1
        try:
            yield
        finally:
            async with self._changed:
                self._busy[name] -= 1
                self._changed.notify_all()

    @asynccontextmanager
    async def exclusive(self, name: str) -> AsyncIterator[None]:
        """Wait until nothing about ``name`` runs, and hold new requests until the end."""
        async with self._changed:
            await self._changed.wait_for(lambda: name not in self._moving)
            self._moving.add(name)
            await self._changed.wait_for(lambda: self._busy[name] == 0)
        try:
            yield
        finally:
            async with self._changed:
                self._moving.discard(name)
                self._changed.notify_all()


def subject(path: str) -> str | None:
    """The model a request of the plain contract is about (None: any shard answers)."""
    parts = path.strip("/").split("/")
    if parts[0] == "models" and len(parts) >= 2 and parts[1]:
        return parts[1]
    if path in ("/revise", "/model"):
        return DEFAULT_MODEL
    return None


def merge_metrics(texts: list[str]) -> str:
    """The shards' Prometheus texts as one, each sample labelled with its ``shard``."""
    families: dict[str, list[str]] = {}
    for shard, text in enumerate(texts):
        family = ""
        for line in text.splitlines():
            if line.startswith("# "):
                family = line.split(" ", 3)[2]
                lines = families.setdefault(family, [])
                if line not in lines:
                    lines.append(line)
            elif line:
                families.setdefault(family, []).append(_labelled(line, shard))
    return "".join(line + "\n" for lines in families.values() for line in lines)


def _labelled(sample: str, shard: int) -> str:
    """A Prometheus sample line with the label ``shard`` first."""
    name, brace, rest = sample.partition("{")
    if not brace:
        name, _, value = sample.partition(" ")
        return f'{name}{{shard="{shard}"}} {value}'
    return f'{name}{{shard="{shard}"{"" if rest.startswith("}") else ","}{rest}'


def ingress_app(settings: Settings, n_shards: int, call: ShardCall) -> FastAPI:
    """The ingress over ``n_shards`` shards reached through ``call``."""
    placement = Placement(n_shards, placement_path(settings))
    gates = Gates()
    limit = max(settings.max_body_bytes, settings.max_snapshot_bytes)

    async def on(shard: int, method: str, *args: Any) -> Any:
        try:
            return await call(shard, method, *args)
        except Exception as error:  # a shard that died or cannot be reached
            log.error("shard %d did not answer %s: %r", shard, method, error)
            raise ShardUnavailable(f"shard {shard} did not answer ({type(error).__name__}); "
                                   "it restarts from its files: send again") from error

    async def forward(shard: int, request: asgi.Request) -> asgi.Reply:
        reply: asgi.Reply = await on(shard, "request", request)
        return reply

    @asynccontextmanager
    async def lifespan(_: FastAPI) -> AsyncIterator[None]:
        await on(placement.owner(DEFAULT_MODEL), "ensure_default")
        log.info("ingress over %d shards", n_shards)
        yield

    api = FastAPI(title="e-FSM safety shield (sharded)", version=app.__version__,
                  lifespan=lifespan)
    api.state.settings = settings
    api.state.placement = placement
    errors.install(api)

    @api.get("/healthz")
    async def healthz() -> dict[str, str]:
        """The ingress is alive (no token needed)."""
        return {"status": "ok"}

    @api.get("/readyz")
    async def readyz() -> JSONResponse:
        """Every shard has loaded its models (no token needed)."""
        try:
            infos = await asyncio.gather(*(on(i, "info") for i in range(n_shards)))
        except ShardUnavailable as error:
            return JSONResponse({"status": "loading", "reason": error.message}, 503)
        ready = all(info["ready"] for info in infos)
        body = {"status": "ready" if ready else "loading",
                "models": sum(len(info["models"]) for info in infos),
                "quarantined": {k: v for info in infos for k, v in info["quarantined"].items()}}
        return JSONResponse(body, status_code=200 if ready else 503)

    @api.get("/shards")
    async def shards(request: Request) -> dict[str, Any]:
        """Each shard: where it runs and the models it owns; and the models moved."""
        check_token(request)
        infos = await asyncio.gather(*(on(i, "info") for i in range(n_shards)))
        return {"shards": infos, "moved": placement.moved}

    @api.post("/shards/move")
    async def move(body: MoveRequest, request: Request) -> Response:
        """Move a model to another shard without losing a step: its requests wait, it is
        snapshotted, restored on the target, deleted from the source, and they resume."""
        check_token(request)
        if body.to >= n_shards:
            raise UnknownShard(f"the cluster has shards 0 to {n_shards - 1}", field="to")
        name, auth = body.model, _auth(request)
        async with gates.exclusive(name):
            source = placement.owner(name)
            if source != body.to:
                snapshot = await forward(source, asgi.Request(
                    "GET", f"/models/{name}", b"format=npz", auth))
                if snapshot.status != 200:
                    return _response(snapshot)
                restored = await forward(body.to, asgi.Request(
                    "PUT", f"/models/{name}", b"",
                    (*auth, (b"content-type", b"application/x-npz")), snapshot.body))
                if restored.status != 200:
                    return _response(restored)
                placement.move(name, body.to)
                await forward(source, asgi.Request("DELETE", f"/models/{name}", b"", auth))
                log.info("model %r moved from shard %d to shard %d", name, source, body.to)
        return JSONResponse({"model": name, "from": source, "to": body.to})

    @api.get("/models")
    async def list_models(request: Request) -> Response:
        """Every model of every shard, by name."""
        replies = await asyncio.gather(*(forward(i, _copy(request, b"")) for i in range(n_shards)))
        for reply in replies:
            if reply.status != 200:
                return _response(reply)
        models = [model for i, reply in enumerate(replies)
                  for model in json.loads(reply.body)["models"]
                  if placement.owner(model["name"]) == i]  # not a copy left by a broken move
        return JSONResponse({"models": sorted(models, key=lambda m: m["name"])})

    @api.get("/metrics")
    async def metrics(request: Request) -> Response:
        """The shards' metrics, each sample with its ``shard`` label (Prometheus text)."""
        replies = await asyncio.gather(*(forward(i, _copy(request, b"")) for i in range(n_shards)))
        for reply in replies:
            if reply.status != 200:
                return _response(reply)
        return Response(merge_metrics([r.body.decode() for r in replies]),
                        media_type="text/plain; version=0.0.4; charset=utf-8")

    @api.websocket("/models/{name}/ws")
    async def model_stream(websocket: WebSocket, name: NamePath) -> None:
        """A stream of steps for one model, each frame answered by the model's owner."""
        if not token_ok(settings.token, given_token(websocket.headers, websocket.query_params)):
            await websocket.close(code=POLICY_VIOLATION, reason="missing or wrong bearer token")
            return
        await websocket.accept()

        async def reply(text: str) -> str:
            try:
                async with gates.use(name):
                    answer: str = await on(placement.owner(name), "frame", name, text)
                    return answer
            except ShieldError as error:
                return json.dumps(error_body(error.code, error.message, error.field))

        try:
            async with gates.use(name):
                refusal = await on(placement.owner(name), "refusal", name)
        except ShieldError as error:
            refusal = error_body(error.code, error.message, error.field)
        if refusal is not None:
            await refuse(websocket, refusal)
            return
        await serve_frames(websocket, settings.max_body_bytes, reply)

    @api.websocket("/ws")
    async def default_stream(websocket: WebSocket) -> None:
        """A stream of steps for the 'default' model."""
        await model_stream(websocket, DEFAULT_MODEL)

    @api.api_route("/{path:path}", methods=METHODS, include_in_schema=False)
    async def anything(path: str, request: Request) -> Response:
        """Every other route of the plain contract, answered by the shard of its model."""
        body = await _read(request, limit)
        names = _named(request.method, request.url.path, body)
        if request.url.path.endswith("/events") and names:
            return JSONResponse(error_body(
                "not_found", "a sharded service has no live event feed: watch a model on "
                "python -m app serve"), status_code=404)
        async with AsyncExitStack() as held:
            for name in sorted(set(names)):
                await held.enter_async_context(gates.use(name))
            owners = {placement.owner(name) for name in names}
            if len(owners) > 1:
                raise SeveralShards(
                    "a batch across models must name models of one shard (see GET /shards; "
                    "POST /shards/move puts models together)", field="steps")
            reply = await forward(owners.pop() if owners else 0, _copy(request, body))
        if request.method == "DELETE" and reply.status == 204 and len(names) == 1:
            placement.forget(names[0])
        return _response(reply)

    return api


def _named(method: str, path: str, body: bytes) -> list[str]:
    """The models a request is about: its path's, or those its body names when it creates a
    model or steps several (an unreadable body names none: shard 0 answers its error)."""
    if path in ("/models", "/revise/batch") and method == "POST":
        try:
            document = json.loads(body)
        except ValueError:
            return []
        if not isinstance(document, dict):
            return []
        if path == "/models":
            return [document["name"]] if isinstance(document.get("name"), str) else []
        steps = document.get("steps")
        return [s["model"] for s in steps if isinstance(s, dict) and isinstance(
            s.get("model"), str)] if isinstance(steps, list) else []
    name = subject(path)
    return [] if name is None else [name]


async def _read(request: Request, limit: int) -> bytes:
    """The request's body, refused past ``limit`` bytes before it is all read."""
    chunks, size = [], 0
    async for chunk in request.stream():
        size += len(chunk)
        if size > limit:
            raise TooLarge(f"request body over {limit} bytes", field="body")
        chunks.append(chunk)
    return b"".join(chunks)


def _copy(request: Request, body: bytes) -> asgi.Request:
    return asgi.Request(request.method, request.url.path, request.scope["query_string"],
                        tuple(request.scope["headers"]), body)


def _auth(request: Request) -> tuple[tuple[bytes, bytes], ...]:
    return tuple((k, v) for k, v in request.scope["headers"] if k == b"authorization")


def _response(reply: asgi.Reply) -> Response:
    response = Response(reply.body, status_code=reply.status)
    response.raw_headers = list(reply.headers)
    return response
