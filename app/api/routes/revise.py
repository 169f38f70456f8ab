"""POST /revise and friends: one step or a batch of steps in, decision records out."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Depends, Path, Request
from fastapi.responses import Response
from starlette.concurrency import run_in_threadpool

from app.api.convert import to_json, to_step
from app.api.deps import (
    BEARER_DOCUMENTED,
    KnownQueryRoute,
    RegistryDep,
    SettingsDep,
    check_token,
    require_token,
)
from app.api.errors import TooLarge
from app.api.schemas import (
    NAME_PATTERN,
    BatchRequest,
    BatchResponse,
    Decision,
    ErrorBody,
    ModelBatchRequest,
    ReviseRequest,
)
from app.core import Decision as CoreDecision
from app.service.registry import DEFAULT_MODEL, ModelRegistry, Step

ERRORS: dict[int | str, dict[str, object]] = {
    code: {"model": ErrorBody} for code in (401, 404, 413, 422, 503)
}
router = APIRouter(tags=["revise"], responses=ERRORS, route_class=KnownQueryRoute)
NamePath = Annotated[str, Path(pattern=NAME_PATTERN, description="Model name.")]


async def step_one(registry: ModelRegistry, name: str, step: Step) -> CoreDecision:
    """Run inline when the model is free and no fsync waits (one step on the loop), else in
    the threadpool."""
    decision = registry.try_step(name, step) if registry.steps_are_quick else None
    if decision is None:
        decision = await run_in_threadpool(registry.step, name, step)
    return decision


def json_response(content: Any) -> Response:
    return Response(to_json(content), media_type="application/json")


@router.post("/models/{name}/revise", response_model=Decision, openapi_extra=BEARER_DOCUMENTED)
async def revise_model(name: NamePath, body: ReviseRequest, request: Request) -> Response:
    """Answer one proposed action of a stream with the decision record."""
    check_token(request)
    decision = await step_one(request.app.state.registry, name, to_step(body))
    return json_response(decision)


@router.post("/revise", response_model=Decision, openapi_extra=BEARER_DOCUMENTED)
async def revise(body: ReviseRequest, request: Request) -> Response:
    """One step of the 'default' model."""
    return await revise_model(DEFAULT_MODEL, body, request)


def check_size(n: int, limit: int) -> None:
    if n > limit:
        raise TooLarge(f"a batch holds at most {limit} steps, got {n}", field="steps")


@router.post(
    "/models/{name}/revise/batch",
    response_model=BatchResponse,
    dependencies=[Depends(require_token)],
)
def revise_batch(
    name: NamePath, body: BatchRequest, registry: RegistryDep, settings: SettingsDep
) -> Response:
    """Steps of one model, applied in order; one bad step rejects the whole batch."""
    check_size(len(body.steps), settings.max_batch)
    decisions = registry.step_batch(name, [to_step(s) for s in body.steps])
    return json_response({"decisions": decisions})


@router.post("/revise/batch", response_model=BatchResponse, dependencies=[Depends(require_token)])
def revise_across(
    body: ModelBatchRequest, registry: RegistryDep, settings: SettingsDep
) -> Response:
    """Steps across models (each names its model), in order; one bad step rejects them all."""
    check_size(len(body.steps), settings.max_batch)
    decisions = registry.step_many([(s.model, to_step(s)) for s in body.steps])
    assert decisions is not None
    return json_response({"decisions": decisions})
