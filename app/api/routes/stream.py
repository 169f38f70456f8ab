"""WebSocket sessions: each text frame one step, each reply the decision record, in order."""

from __future__ import annotations

import json
from collections.abc import Awaitable, Callable
from typing import Any

from fastapi import APIRouter, WebSocket, WebSocketDisconnect
from pydantic import ValidationError

from app.api.auth import given_token, token_ok
from app.api.convert import to_json, to_step
from app.api.errors import POLICY_VIOLATION, error_body
from app.api.routes.revise import NamePath, step_one
from app.api.schemas import ReviseRequest
from app.core import ShieldError
from app.service.registry import DEFAULT_MODEL, ModelRegistry

router = APIRouter(tags=["stream"])


@router.websocket("/models/{name}/ws")
async def model_stream(websocket: WebSocket, name: NamePath) -> None:
    """A stream of steps for one model over one connection."""
    app = websocket.app
    registry: ModelRegistry = app.state.registry
    if not token_ok(
        app.state.settings.token, given_token(websocket.headers, websocket.query_params)
    ):
        await websocket.close(code=POLICY_VIOLATION, reason="missing or wrong bearer token")
        return
    await websocket.accept()
    unknown = next((key for key in websocket.query_params if key != "token"), None)
    if unknown is not None:  # as over HTTP: a misspelt option is not ignored
        await refuse(
            websocket,
            error_body("invalid_query", "unknown query parameter; a stream takes token", unknown),
        )
        return
    try:
        registry.get(name)
    except ShieldError as error:
        await refuse(websocket, error_body(error.code, error.message, "name"))
        return
    await serve_frames(
        websocket, app.state.settings.max_body_bytes, lambda text: answer(registry, name, text)
    )


async def refuse(websocket: WebSocket, body: dict[str, Any]) -> None:
    """Refuse an accepted stream: one error frame, then the close."""
    await websocket.send_text(json.dumps(body))
    await websocket.close(code=POLICY_VIOLATION)


async def serve_frames(
    websocket: WebSocket, limit: int, reply: Callable[[str], Awaitable[str]]
) -> None:
    """Answer each text frame with ``reply(text)``, in order, until the client leaves; a
    frame that is not text, or over ``limit`` bytes (the body limit of HTTP), gets an error
    frame and the stream goes on."""
    while True:
        try:
            message = await websocket.receive()
        except WebSocketDisconnect:
            return
        if message["type"] == "websocket.disconnect":
            return
        text = message.get("text")
        if text is None:
            await websocket.send_text(
                json.dumps(error_body("unsupported_frame", "send each step as a JSON text frame"))
            )
            continue
        if 4 * len(text) > limit and len(text.encode()) > limit:  # UTF-8: 1-4 bytes a character
            await websocket.send_text(
                json.dumps(error_body("too_large", f"frame over {limit} bytes"))
            )
            continue
        await websocket.send_text(await reply(text))


async def answer(registry: ModelRegistry, name: str, text: str) -> str:
    """The reply to one frame: the decision record, or the error body of a bad step."""
    try:
        body = ReviseRequest.model_validate_json(text)
        decision = await step_one(registry, name, to_step(body))
    except ValidationError as error:
        first = error.errors()[0]
        code = "invalid_json" if first["type"] == "json_invalid" else "invalid_body"
        field = ".".join(str(p) for p in first["loc"]) or None
        return json.dumps(error_body(code, first["msg"], field))
    except ShieldError as error:
        return json.dumps(error_body(error.code, error.message, error.field))
    return to_json(decision).decode()


@router.websocket("/ws")
async def default_stream(websocket: WebSocket) -> None:
    """A stream of steps for the 'default' model."""
    await model_stream(websocket, DEFAULT_MODEL)
