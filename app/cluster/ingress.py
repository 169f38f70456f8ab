"""The ingress of a sharded service: the plain service's HTTP and WebSocket contract, each
request handed to the shard that owns its model.

A request about one model goes to the model's shard: its home shard by name
(:func:`~app.cluster.placement.hashed_owner`), or where the ingress learned it moved. A shard
that gave the model away answers :class:`~app.cluster.shard.Moved`; the ingress remembers the
new shard and sends the request there. So an ingress holds nothing that others must share, and
Serve can run as many as the traffic needs. ``GET /models``, ``/readyz`` and ``/metrics`` ask
every shard. Two routes are the cluster's own: ``GET /shards`` (where each shard runs, what it
holds and gave away) and ``POST /shards/move`` (a model to another shard, handed over by its
shard without losing a step). Shards are reached through ``call(shard, method, *args)``, a
coroutine, and ``stream(shard, method, *args)``, an async iterator (the live event feed):
Ray Serve's handles in :mod:`app.cluster.ray_serve`, the objects themselves in tests.
"""

from __future__ import annotations

import asyncio
import json
import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any

from fastapi import FastAPI, Request, WebSocket
from fastapi.responses import JSONResponse, Response, StreamingResponse
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
from app.cluster.placement import Moves, hashed_owner
from app.cluster.routing import named
from app.cluster.shard import Moved, ShardCall, ShardStream
from app.core import ShieldError, compiled
from app.service.registry import DEFAULT_MODEL
from app.settings import Settings

log = logging.getLogger("app.cluster")

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


def ingress_app(settings: Settings, n_shards: int, call: ShardCall, stream: ShardStream) -> FastAPI:
    """An ingress over ``n_shards`` shards reached through ``call`` and ``stream``."""
    learned = Moves()  # where this ingress saw models go; the shards hold the truth
    limit = max(settings.max_body_bytes, settings.max_snapshot_bytes)

    def owner(name: str) -> int:
        moved = learned.get(name)
        return hashed_owner(name, n_shards) if moved is None else moved

    def learn(moved: Moved) -> None:
        """Remember where a model went (and forget it once it is back home)."""
        if moved.owner == hashed_owner(moved.name, n_shards):
            learned.discard(moved.name)
        else:
            learned.set(moved.name, moved.owner)

    async def on(shard: int, method: str, *args: Any) -> Any:
        try:
            return await call(shard, method, *args)
        except Exception as error:  # a shard that died or cannot be reached
            log.error("shard %d did not answer %s: %r", shard, method, error)
            raise ShardUnavailable(
                f"shard {shard} did not answer ({type(error).__name__}); "
                "it restarts from its files: send again"
            ) from error

    async def routed(names: list[str], method: str, *args: Any) -> Any:
        """``method`` on the shard of ``names``, following the moves the shards report."""
        for _ in range(n_shards + 2):
            owners = {owner(name) for name in names}
            if len(owners) > 1:
                raise SeveralShards(
                    "a batch across models must name models of one shard (see GET /shards; "
                    "POST /shards/move puts models together)",
                    field="steps",
                )
            result = await on(owners.pop() if owners else 0, method, *args)
            if not isinstance(result, Moved):
                return result
            learn(result)
        raise ShardUnavailable(f"{names} kept moving while the request was sent: send again")

    async def streamed(name: str, request: asgi.Request) -> Response:
        """The streamed answer of the shard of ``name``, following the moves it reports."""
        for _ in range(n_shards + 2):
            parts = stream(owner(name), "stream", request)
            try:
                head = await anext(parts)
            except Exception as error:  # a shard that died or cannot be reached
                log.error("shard %d did not answer a stream: %r", owner(name), error)
                raise ShardUnavailable(
                    f"shard {owner(name)} did not answer ({type(error).__name__}): send again"
                ) from error
            if isinstance(head, Moved):
                learn(head)
                continue
            response = StreamingResponse(_bodies(parts), status_code=head.status)
            response.raw_headers = list(head.headers)
            return response
        raise ShardUnavailable(f"{name!r} kept moving while the request was sent: send again")

    async def every(method: str, *args: Any) -> list[Any]:
        return list(await asyncio.gather(*(on(i, method, *args) for i in range(n_shards))))

    async def everywhere(request: Request) -> tuple[list[asgi.Reply], asgi.Reply | None]:
        """A request without a body answered by every shard, and the first refusal."""
        replies: list[asgi.Reply] = await every("request", _copy(request, b""))
        return replies, next((r for r in replies if r.status != 200), None)

    @asynccontextmanager
    async def lifespan(_: FastAPI) -> AsyncIterator[None]:
        await routed([DEFAULT_MODEL], "ensure_default")
        log.info("ingress over %d shards", n_shards)
        yield

    api = FastAPI(title="e-FSM safety shield (sharded)", version=app.__version__, lifespan=lifespan)
    api.state.settings = settings
    errors.install(api)

    @api.get("/healthz")
    async def healthz() -> dict[str, str]:
        """The ingress is alive (no token needed), with the version and the e-FSM of the
        package it and its shards run (as the plain service's)."""
        return {"status": "ok", "version": app.__version__, "core": compiled.version()}

    @api.get("/readyz")
    async def readyz() -> JSONResponse:
        """Every shard has loaded its models (no token needed)."""
        try:
            infos = await every("info")
        except ShardUnavailable as error:
            return JSONResponse({"status": "loading", "reason": error.message}, 503)
        ready = all(info["ready"] for info in infos)
        body = {
            "status": "ready" if ready else "loading",
            "models": sum(len(info["models"]) for info in infos),
            "quarantined": {k: v for info in infos for k, v in info["quarantined"].items()},
        }
        return JSONResponse(body, status_code=200 if ready else 503)

    @api.get("/shards")
    async def shards(request: Request) -> dict[str, Any]:
        """Each shard: where it runs, the models it holds and those it gave away."""
        check_token(request)
        return {"shards": await every("info")}

    @api.post("/shards/move")
    async def move(body: MoveRequest, request: Request) -> Response:
        """Move a model to another shard without losing a step: its requests wait, it is
        snapshotted, restored on the target and deleted from the source, and they resume."""
        check_token(request)
        if body.to >= n_shards:
            raise UnknownShard(f"the cluster has shards 0 to {n_shards - 1}", field="to")
        reply: asgi.Reply = await routed([body.model], "move", body.model, body.to)
        if reply.status == 200:
            learn(Moved(body.model, body.to))
        return _response(reply)

    @api.get("/models")
    async def list_models(request: Request) -> Response:
        """Every model of every shard, by name."""
        replies, refused = await everywhere(request)
        if refused is not None:
            return _response(refused)
        models = [m for reply in replies for m in json.loads(reply.body)["models"]]
        return JSONResponse({"models": sorted(models, key=lambda m: m["name"])})

    @api.get("/metrics")
    async def metrics(request: Request) -> Response:
        """The shards' metrics, each sample with its ``shard`` label (Prometheus text)."""
        replies, refused = await everywhere(request)
        if refused is not None:
            return _response(refused)
        return Response(
            merge_metrics([r.body.decode() for r in replies]),
            media_type="text/plain; version=0.0.4; charset=utf-8",
        )

    @api.websocket("/models/{name}/ws")
    async def model_stream(websocket: WebSocket, name: NamePath) -> None:
        """A stream of steps for one model, each frame answered by the model's shard."""
        if not token_ok(settings.token, given_token(websocket.headers, websocket.query_params)):
            await websocket.close(code=POLICY_VIOLATION, reason="missing or wrong bearer token")
            return
        await websocket.accept()

        async def reply(text: str) -> str:
            try:
                answer: str = await routed([name], "frame", name, text)
                return answer
            except ShieldError as error:
                return json.dumps(error_body(error.code, error.message, error.field))

        try:
            refusal = await routed([name], "refusal", name)
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
        names = named(request.method, request.url.path, body)
        if len(names) == 1 and request.url.path.endswith("/events"):
            return await streamed(names[0], _copy(request, body))
        return _response(await routed(names, "request", _copy(request, body)))

    return api


async def _bodies(parts: AsyncIterator[Any]) -> AsyncIterator[bytes]:
    """The pieces of a streamed body (after its head)."""
    async for part in parts:
        yield part


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
    return asgi.Request(
        request.method,
        request.url.path,
        request.scope["query_string"],
        tuple(request.scope["headers"]),
        body,
    )


def _response(reply: asgi.Reply) -> Response:
    response = Response(reply.body, status_code=reply.status)
    response.raw_headers = list(reply.headers)
    return response
