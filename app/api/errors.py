"""One table from errors to statuses, and the handlers that give every error the same body."""

from __future__ import annotations

import json
import logging
from collections.abc import Sequence
from typing import Any

from fastapi import FastAPI, Request, WebSocket
from fastapi.exceptions import RequestValidationError, WebSocketRequestValidationError
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException
from starlette.requests import HTTPConnection

from app.api.auth import given_token, token_ok
from app.core import InvalidConfig, InvalidSnapshot, ShieldError
from app.service.idempotency import KeyReused, TooManyKeys
from app.service.registry import (
    InvalidName,
    ModelExists,
    ModelQuarantined,
    TooManyModels,
    UnknownModel,
)

log = logging.getLogger("app.api")
POLICY_VIOLATION = 1008  # the WebSocket close code of a refused stream

STATUS: dict[type[ShieldError], int] = {
    UnknownModel: 404,
    ModelExists: 409,
    ModelQuarantined: 503,
    TooManyModels: 409,
    InvalidName: 422,
    InvalidConfig: 422,
    InvalidSnapshot: 422,
    KeyReused: 422,
    TooManyKeys: 413,
}


class Unauthorized(ShieldError):
    """A missing or wrong bearer token."""

    code = "unauthorized"


class InvalidQuery(ShieldError):
    """A query parameter names something the model does not have (an action bin)."""

    code = "invalid_query"


class NotFound(ShieldError):
    """A path names something the model does not have (a state)."""

    code = "not_found"


class TooLarge(ShieldError):
    """A body or batch over the configured limit."""

    code = "too_large"


STATUS.update({Unauthorized: 401, TooLarge: 413, InvalidQuery: 422, NotFound: 404})


def error_body(code: str, message: str, field: str | None = None) -> dict[str, Any]:
    return {"error": {"code": code, "message": message, "field": field}}


def status_of(error: ShieldError) -> int:
    for kind in type(error).__mro__:
        if kind in STATUS:
            return STATUS[kind]
    return 422


def shield_error(_: Request, error: Exception) -> JSONResponse:
    assert isinstance(error, ShieldError)
    headers = {"WWW-Authenticate": "Bearer"} if isinstance(error, Unauthorized) else None
    return JSONResponse(
        error_body(error.code, error.message, error.field),
        status_code=status_of(error),
        headers=headers,
    )


def validation_error(request: Request, error: Exception) -> JSONResponse:
    """422 naming the input at fault; 401 first when the token is missing or wrong (routes
    on the per-step path check it after validation)."""
    assert isinstance(error, RequestValidationError)
    if not _authorised(request):
        return shield_error(request, Unauthorized("missing or wrong bearer token"))
    return JSONResponse(_first_error(error.errors()), status_code=422)


async def websocket_validation_error(websocket: WebSocket, error: Exception) -> None:
    """A stream refused before it starts (a bad model name in its path): the error frame and
    the close of an unknown model's stream, not a bare close whose reason echoes the input;
    without the token, the close of a stream without it."""
    assert isinstance(error, WebSocketRequestValidationError)
    if not _authorised(websocket):
        await websocket.close(code=POLICY_VIOLATION, reason="missing or wrong bearer token")
        return
    await websocket.accept()
    await websocket.send_text(json.dumps(_first_error(error.errors())))
    await websocket.close(code=POLICY_VIOLATION)


def _authorised(connection: HTTPConnection) -> bool:
    """The token as the route would take it: WebSockets may carry it in the query."""
    query = connection.query_params if connection.scope["type"] == "websocket" else {}
    return token_ok(connection.app.state.settings.token, given_token(connection.headers, query))


def _first_error(errors: Sequence[Any]) -> dict[str, Any]:
    """The error body of the first of pydantic's errors."""
    first = errors[0]
    if first.get("type") == "json_invalid":  # loc holds a character position, not a field
        return error_body("invalid_json", first.get("msg", "invalid JSON"))
    where, *loc = [str(p) for p in first.get("loc", ("body",))]
    return error_body(
        _code_of(first.get("type", ""), where),
        first.get("msg", "invalid request"),
        ".".join(loc) or None,
    )


def _code_of(kind: str, where: str) -> str:
    """``invalid_name`` for a model name (the only input with a pattern), wherever it stands;
    otherwise the part of the request at fault: ``invalid_body``, ``invalid_query``..."""
    if kind == "string_pattern_mismatch":
        return InvalidName.code
    return f"invalid_{where}" if where in ("body", "query", "path") else "invalid_request"


def http_error(_: Request, error: Exception) -> JSONResponse:
    assert isinstance(error, HTTPException)
    if error.status_code == 400:  # FastAPI could not read the body (UTF-8, nesting): not JSON
        return JSONResponse(
            error_body("invalid_json", f"the body is not JSON: {error.detail}"), status_code=422
        )
    code = {404: "not_found", 405: "method_not_allowed"}.get(error.status_code, "http_error")
    return JSONResponse(
        error_body(code, str(error.detail)), status_code=error.status_code, headers=error.headers
    )


def internal_error(request: Request, error: Exception) -> JSONResponse:
    log.error("unhandled error on %s %s", request.method, request.url.path, exc_info=error)
    return JSONResponse(error_body("internal", "internal error"), status_code=500)


def install(app: FastAPI) -> None:
    """Register the handlers."""
    app.add_exception_handler(ShieldError, shield_error)
    app.add_exception_handler(RequestValidationError, validation_error)
    app.add_exception_handler(WebSocketRequestValidationError, websocket_validation_error)
    app.add_exception_handler(HTTPException, http_error)
    app.add_exception_handler(Exception, internal_error)
