"""One table from errors to statuses, and the handlers that give every error the same body."""

from __future__ import annotations

import logging
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException

from app.core import InvalidConfig, InvalidSnapshot, ShieldError
from app.service.registry import InvalidName, ModelExists, UnknownModel

log = logging.getLogger("app.api")

STATUS: dict[type[ShieldError], int] = {
    UnknownModel: 404,
    ModelExists: 409,
    InvalidName: 422,
    InvalidConfig: 422,
    InvalidSnapshot: 422,
}


class Unauthorized(ShieldError):
    """A missing or wrong bearer token."""

    code = "unauthorized"


class TooLarge(ShieldError):
    """A body or batch over the configured limit."""

    code = "too_large"


STATUS.update({Unauthorized: 401, TooLarge: 413})


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
    return JSONResponse(error_body(error.code, error.message, error.field),
                        status_code=status_of(error), headers=headers)


def validation_error(_: Request, error: Exception) -> JSONResponse:
    assert isinstance(error, RequestValidationError)
    first = error.errors()[0]
    if first.get("type") == "json_invalid":  # loc holds a character position, not a field
        return JSONResponse(error_body("invalid_json", first.get("msg", "invalid JSON")),
                            status_code=422)
    where, *loc = [str(p) for p in first.get("loc", ("body",))]
    return JSONResponse(error_body(_code_of(first.get("type", ""), where),
                                   first.get("msg", "invalid request"), ".".join(loc) or None),
                        status_code=422)


def _code_of(kind: str, where: str) -> str:
    """``invalid_name`` for a model name (the only input with a pattern), wherever it stands;
    otherwise the part of the request at fault: ``invalid_body``, ``invalid_query``..."""
    if kind == "string_pattern_mismatch":
        return InvalidName.code
    return f"invalid_{where}" if where in ("body", "query", "path") else "invalid_request"


def http_error(_: Request, error: Exception) -> JSONResponse:
    assert isinstance(error, HTTPException)
    code = {404: "not_found", 405: "method_not_allowed"}.get(error.status_code, "http_error")
    return JSONResponse(error_body(code, str(error.detail)), status_code=error.status_code,
                        headers=error.headers)


def internal_error(request: Request, error: Exception) -> JSONResponse:
    log.error("unhandled error on %s %s", request.method, request.url.path, exc_info=error)
    return JSONResponse(error_body("internal", "internal error"), status_code=500)


def install(app: FastAPI) -> None:
    """Register the handlers."""
    app.add_exception_handler(ShieldError, shield_error)
    app.add_exception_handler(RequestValidationError, validation_error)
    app.add_exception_handler(HTTPException, http_error)
    app.add_exception_handler(Exception, internal_error)
