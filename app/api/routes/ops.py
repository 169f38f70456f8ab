"""Health, readiness and Prometheus metrics."""

from __future__ import annotations

from fastapi import APIRouter, Depends, Request, Response
from fastapi.responses import JSONResponse
from prometheus_client import CONTENT_TYPE_LATEST, generate_latest

import app
from app.api.deps import KnownQueryRoute, RegistryDep, require_token
from app.core import compiled

router = APIRouter(tags=["operations"], route_class=KnownQueryRoute)


@router.get("/healthz")
def healthz() -> dict[str, str]:
    """The process is alive (no token needed), with the version it serves and its e-FSM's
    (``core``: :func:`app.core.compiled.version`, as experiment records name it)."""
    return {"status": "ok", "version": app.__version__, "core": compiled.version()}


@router.get("/readyz")
def readyz(registry: RegistryDep) -> JSONResponse:
    """The models are loaded (no token needed); models set aside for damaged files are
    named with the reason (the others serve)."""
    ready = registry.ready
    body = {
        "status": "ready" if ready else "loading",
        "models": len(registry.names()),
        "quarantined": registry.quarantined,
    }
    return JSONResponse(body, status_code=200 if ready else 503)


@router.get(
    "/metrics",
    dependencies=[Depends(require_token)],
    responses={200: {"content": {"text/plain": {}}, "description": "Prometheus text format."}},
)
def metrics(request: Request) -> Response:
    """Prometheus text format."""
    return Response(
        generate_latest(request.app.state.metrics.registry), media_type=CONTENT_TYPE_LATEST
    )
