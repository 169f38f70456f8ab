"""One shard: the plain service over a data directory of its own, answering in process what
the ingress forwards. A shard that restarts loads its models from their files (snapshots and
journals), as ``python -m app serve`` does."""

from __future__ import annotations

import logging
import os
import socket
from typing import Any

from app.api.errors import error_body
from app.api.routes.stream import answer
from app.cluster.asgi import Reply, Request, call
from app.core import ShieldError
from app.main import create_app
from app.service.registry import ModelRegistry
from app.settings import Settings

log = logging.getLogger("app.cluster")


def shard_dir(settings: Settings, index: int) -> Settings:
    """The settings of shard ``index``: the cluster's, with ``<data_dir>/shards/<index>``."""
    if settings.data_dir is None:
        return settings
    return settings.model_copy(update={"data_dir": settings.data_dir / "shards" / str(index)})


class ShardServer:
    """The models of one shard, behind the plain service's routes."""

    def __init__(self, settings: Settings, index: int) -> None:
        self.index = index
        self.app = create_app(shard_dir(settings, index), create_default=False)
        self.registry: ModelRegistry = self.app.state.registry
        self.registry.open()
        log.info("shard %d (pid %d): %d models loaded", index, os.getpid(),
                 len(self.registry.names()))

    async def request(self, request: Request) -> Reply:
        """An HTTP request of the service's contract, answered by this shard's app."""
        return await call(self.app, request)

    async def frame(self, name: str, text: str) -> str:
        """One WebSocket frame (a step of model ``name``): the decision record or an error."""
        return await answer(self.app, self.registry, name, text)

    async def refusal(self, name: str) -> dict[str, Any] | None:
        """The error body that refuses a stream of model ``name``, or None if it serves."""
        try:
            self.registry.get(name)
        except ShieldError as error:
            return error_body(error.code, error.message, "name")
        return None

    async def ensure_default(self) -> None:
        """Create the 'default' model here (this shard owns its name)."""
        self.registry.ensure_default()

    async def info(self) -> dict[str, Any]:
        """Where this shard runs and what it holds."""
        return {"shard": self.index, "host": socket.gethostname(), "pid": os.getpid(),
                "ready": self.registry.ready, "models": self.registry.names(),
                "quarantined": self.registry.quarantined}

    def close(self) -> None:
        """Snapshot every model and close its files."""
        self.registry.close()
