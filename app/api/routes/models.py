"""Models: create, list, snapshot (JSON or .npz), history, restore, delete, reset."""

from __future__ import annotations

import json
from typing import Annotated, Any, Literal

from fastapi import APIRouter, Depends, Header, Query, Request, Response, status
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import JSONResponse

from app.api.deps import KnownQueryRoute, RegistryDep, require_token
from app.api.errors import InvalidQuery, TooLarge
from app.api.routes.revise import ERRORS, NamePath
from app.api.schemas import ErrorBody, ModelCreate, ModelHistory, ModelList, ModelSummary
from app.core import InvalidConfig, InvalidSnapshot, ShieldConfig
from app.service import codec
from app.service.registry import DEFAULT_MODEL, Model, ModelRegistry

router = APIRouter(
    tags=["models"],
    dependencies=[Depends(require_token)],
    responses=ERRORS,
    route_class=KnownQueryRoute,
)
NPZ = "application/x-npz"


def summary(model: Model) -> dict[str, Any]:
    c = model.shield.counters
    return {
        "name": model.name,
        "n_states": model.shield.n_states,
        "steps": c.steps,
        "episodes": c.episodes,
        "model_version": c.model_version,
        "interventions": dict(c.interventions),
        "streams": len(model.shield.streams),
    }


@router.post(
    "/models",
    status_code=status.HTTP_201_CREATED,
    response_model=ModelSummary,
    responses={409: {"model": ErrorBody, "description": "model_exists or too_many_models"}},
)
def create_model(body: ModelCreate, registry: RegistryDep) -> dict[str, Any]:
    """Create an empty model with the paper's configuration and the given overrides."""
    try:  # the core's bounds, then the server's: either names the body's field
        return summary(registry.create(body.name, ShieldConfig.from_dict(body.config)))
    except InvalidConfig as error:
        error.field = f"config.{error.field}" if error.field else "config"
        raise


@router.get("/models", response_model=ModelList)
def list_models(registry: RegistryDep) -> dict[str, Any]:
    """Every model with its counters."""
    return {"models": [summary(registry.get(n)) for n in registry.names()]}


@router.get(
    "/models/{name}",
    responses={
        200: {
            "content": {"application/json": {}, NPZ: {}},
            "description": "The snapshot: readable views plus the exact state.",
        }
    },
)
def get_model(
    name: NamePath,
    registry: RegistryDep,
    tpm: Annotated[
        Literal["dense", "sparse", "none"],
        Query(description="Transition matrices: all entries, those >= min_prob, or none."),
    ] = "sparse",
    action: Annotated[int | None, Query(ge=0, description="Only this action bin's matrix.")] = None,
    min_prob: Annotated[float, Query(gt=0, le=1)] = 1e-3,
    exact: Annotated[bool, Query(description="Include the exact state that PUT restores.")] = True,
    format: Annotated[Literal["json", "npz"] | None, Query()] = None,
    accept: Annotated[str | None, Header()] = None,
) -> Response:
    """The snapshot of a model: configuration, counters, states, matrices, exact state."""
    model = registry.get(name)
    with model.lock:
        shield = model.shield
        if action is not None and action >= shield.config.action.n_bins:
            raise InvalidQuery(f"action bin {action} does not exist", field="action")
        if format == "npz" or (format is None and accept is not None and NPZ in accept):
            return Response(
                codec.to_npz(shield.snapshot()),
                media_type=NPZ,
                headers={"Content-Disposition": f'attachment; filename="{name}.npz"'},
            )
        body: dict[str, Any] = {
            **summary(model),
            "config": shield.config.to_dict(),
            **codec.readable(shield, tpm, action, min_prob),
        }
        if exact:
            body["exact"] = codec.to_json(shield.snapshot())
    return JSONResponse(body)


@router.get("/models/{name}/history", response_model=ModelHistory)
def get_history(name: NamePath, registry: RegistryDep) -> dict[str, Any]:
    """A model's totals at the end of its episodes, thinned to span its whole life, and now."""
    model = registry.get(name)
    with model.lock:
        return {"name": name, **model.shield.history_view()}


@router.get("/model", include_in_schema=True)
def get_default_model(
    registry: RegistryDep,
    tpm: Literal["dense", "sparse", "none"] = "sparse",
    action: Annotated[int | None, Query(ge=0)] = None,
    min_prob: Annotated[float, Query(gt=0, le=1)] = 1e-3,
    exact: bool = True,
    format: Literal["json", "npz"] | None = None,
    accept: Annotated[str | None, Header()] = None,
) -> Response:
    """The snapshot of the 'default' model."""
    return get_model(DEFAULT_MODEL, registry, tpm, action, min_prob, exact, format, accept)


@router.put(
    "/models/{name}",
    response_model=ModelSummary,
    openapi_extra={
        "requestBody": {
            "content": {
                "application/json": {"schema": {"type": "object"}},
                NPZ: {"schema": {"type": "string", "format": "binary"}},
            }
        }
    },
)
async def put_model(name: NamePath, request: Request, registry: RegistryDep) -> dict[str, Any]:
    """Create or replace a model from a snapshot (the JSON of GET, or its .npz)."""
    async with request.app.state.restores:  # memory: at most this many read at once
        blob = await request.body()
        npz = NPZ in request.headers.get("content-type", "")
        limit = request.app.state.settings.max_snapshot_bytes
        model = await run_in_threadpool(restore, registry, name, blob, npz, limit)
    return summary(model)


JSON_INFLATION = 8  # a JSON snapshot's Python objects take up to this many times its bytes


def restore(registry: ModelRegistry, name: str, blob: bytes, npz: bool, limit: int) -> Model:
    """Read a snapshot (``limit``: the most its arrays may take) and restore it: a JSON one
    of at most ``limit / JSON_INFLATION`` bytes, whose parsed objects then take no more than
    the arrays of an .npz may."""
    if npz:
        return registry.restore(name, codec.from_npz(blob, limit))
    if len(blob) > limit // JSON_INFLATION:
        raise TooLarge(
            f"a JSON snapshot over {limit // JSON_INFLATION} bytes (parsed, it "
            f"would take about {JSON_INFLATION} times as much): send its .npz",
            field="body",
        )
    try:
        document = json.loads(blob)
    except (ValueError, RecursionError) as error:
        raise InvalidSnapshot(f"unreadable snapshot: {error}", field="body") from error
    if not isinstance(document, dict) or "exact" not in document:
        raise InvalidSnapshot("the body needs the 'exact' state of GET", field="exact")
    return registry.restore(name, codec.from_json(document["exact"], limit))


@router.delete("/models/{name}", status_code=status.HTTP_204_NO_CONTENT)
def delete_model(name: NamePath, registry: RegistryDep) -> Response:
    """Remove a model and its stored files."""
    registry.delete(name)
    return Response(status_code=status.HTTP_204_NO_CONTENT)


@router.post("/models/{name}/reset", response_model=ModelSummary)
def reset_model(name: NamePath, registry: RegistryDep) -> dict[str, Any]:
    """Empty a model: back to no states."""
    return summary(registry.reset(name))
