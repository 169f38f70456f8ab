"""Live views for people: a server-sent event feed of a model's steps, one state's details,
and the dashboard page that shows them."""

from __future__ import annotations

import asyncio
import json
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Annotated, Any

from fastapi import APIRouter, Depends, HTTPException, Query, Request
from fastapi import Path as PathParam
from fastapi.responses import FileResponse, RedirectResponse, StreamingResponse

from app.api.auth import given_token, token_ok
from app.api.deps import KnownQueryRoute, RegistryDep, require_token
from app.api.errors import NotFound, Unauthorized
from app.api.routes.revise import ERRORS, NamePath

STATIC = Path(__file__).resolve().parents[2] / "dashboard"
QUEUE = 2000  # events kept for a slow watcher; past that new ones are dropped (and counted)

router = APIRouter(tags=["live"], responses=ERRORS, route_class=KnownQueryRoute)


@router.get("/models/{name}/events", response_class=StreamingResponse)
async def events(
    name: NamePath,
    request: Request,
    registry: RegistryDep,
    token: Annotated[
        str | None, Query(description="For EventSource, which cannot send headers.")
    ] = None,
) -> StreamingResponse:
    """Server-sent events: one ``data:`` line per step of the model (its decision record, the
    observation, and the state when one appears or is flagged)."""
    if not token_ok(
        request.app.state.settings.token,
        given_token(request.headers, {"token": token} if token else {}),
    ):
        raise Unauthorized("missing or wrong bearer token")
    model = registry.get(name)
    loop = asyncio.get_running_loop()
    queue: asyncio.Queue[dict[str, Any]] = asyncio.Queue(QUEUE)
    dropped = 0

    def offer(event: dict[str, Any]) -> None:
        nonlocal dropped
        if queue.full():
            dropped += 1
        else:
            queue.put_nowait(event)

    def push(event: dict[str, Any]) -> None:  # from whichever thread applied the step
        loop.call_soon_threadsafe(offer, event)

    unsubscribe = registry.watch(name, push)
    hello = {
        "type": "hello",
        "n_states": model.shield.n_states,
        "model_version": model.shield.counters.model_version,
    }

    async def stream() -> AsyncIterator[str]:
        try:
            yield f"retry: 1000\ndata: {json.dumps(hello)}\n\n"
            while not await request.is_disconnected():
                try:
                    event = await asyncio.wait_for(queue.get(), timeout=10)
                except TimeoutError:
                    yield f"data: {json.dumps({'type': 'ping', 'dropped': dropped})}\n\n"
                    continue
                yield f"data: {json.dumps(event)}\n\n"
        finally:
            unsubscribe()

    return StreamingResponse(
        stream(),
        media_type="text/event-stream",
        headers={"Cache-Control": "no-cache", "X-Accel-Buffering": "no"},
    )


@router.get("/models/{name}/states/{index}", dependencies=[Depends(require_token)])
def state(
    name: NamePath,
    index: Annotated[int, PathParam(ge=0, description="State index.")],
    registry: RegistryDep,
    top: Annotated[int, Query(ge=1, le=50)] = 5,
) -> dict[str, Any]:
    """One state and, per action, its most likely next states."""
    model = registry.get(name)
    with model.lock:
        shield = model.shield
        if not 0 <= index < shield.n_states:
            raise NotFound(f"no state {index}", field="index")
        return {
            **shield.state_view(index),
            "next": [
                {"bin": a, "states": [{"state": j, "prob": p} for j, p in row]}
                for a, row in enumerate(shield.next_states(index, top))
            ],
        }


@router.get("/", include_in_schema=False)
def root() -> RedirectResponse:
    return RedirectResponse("/dashboard")


@router.get("/dashboard", include_in_schema=False)
def dashboard(
    model: Annotated[
        str | None, Query(description="The model the page opens on; its script reads it.")
    ] = None,
) -> FileResponse:
    """The page; it holds no data, so it needs no token (its requests do)."""
    return FileResponse(STATIC / "index.html")


@router.get("/dashboard/{asset}", include_in_schema=False)
def asset(asset: str) -> FileResponse:
    if asset not in ("app.js", "style.css"):
        raise HTTPException(404, "no such file")
    return FileResponse(STATIC / asset)
