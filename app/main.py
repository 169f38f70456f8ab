"""The FastAPI application: lifespan (models and journals), routers, errors, middleware."""

from __future__ import annotations

import asyncio
import json
import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

from fastapi import FastAPI

import app
from app.api import errors
from app.api.metrics import AppMetrics
from app.api.middleware import BodyLimit, Metrics
from app.api.routes import models, ops, revise, stream, watch
from app.core import ShieldConfig
from app.service.limits import ModelLimits
from app.service.registry import ModelRegistry
from app.settings import Settings, get_settings

log = logging.getLogger("app")


def default_config(settings: Settings) -> ShieldConfig:
    """The configuration of the 'default' model: the settings' file, else the paper's."""
    if settings.config is None:
        return ShieldConfig()
    return ShieldConfig.from_dict(json.loads(settings.config.read_text()))


def model_limits(settings: Settings) -> ModelLimits:
    """What a model of this server may be (:mod:`app.service.limits`)."""
    return ModelLimits(
        settings.max_states,
        settings.max_action_bins,
        settings.max_dimensions,
        settings.max_model_bytes,
    )


def create_app(settings: Settings | None = None, *, create_default: bool = True) -> FastAPI:
    """Build the service; models load (journals replay) when the app starts. A shard of a
    cluster (:mod:`app.cluster`) passes ``create_default=False``: the 'default' model lives on
    the one shard that owns its name."""
    settings = settings or get_settings()
    registry = ModelRegistry(
        settings.data_dir,
        settings.fsync,
        settings.snapshot_every,
        default_config(settings),
        max_models=settings.max_models,
        limits=model_limits(settings),
        create_default=create_default,
        idempotency_window=settings.idempotency_window,
    )

    @asynccontextmanager
    async def lifespan(_: FastAPI) -> AsyncIterator[None]:
        registry.open()
        if settings.data_dir is None:
            log.warning("no data directory: models live in memory only and are lost on exit")
        else:
            log.info("models stored in %s (fsync=%s)", settings.data_dir, settings.fsync)
        yield
        registry.close()

    api = FastAPI(
        title="e-FSM safety shield",
        version=app.__version__,
        summary="An online evolving model that revises a controller's proposed actions.",
        lifespan=lifespan,
    )
    api.state.settings = settings
    api.state.registry = registry
    api.state.restores = asyncio.Semaphore(settings.max_concurrent_restores)  # PUT /models/{name}
    api.state.metrics = AppMetrics(registry)
    errors.install(api)
    for router in (revise.router, models.router, stream.router, ops.router, watch.router):
        api.include_router(router)
    api.add_middleware(
        BodyLimit, limit=settings.max_body_bytes, snapshot_limit=settings.max_snapshot_bytes
    )
    api.add_middleware(
        Metrics, requests=api.state.metrics.requests, latency=api.state.metrics.latency
    )
    return api
