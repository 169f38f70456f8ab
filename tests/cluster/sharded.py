"""The sharded service in one process: the ingress over :class:`ShardServer` objects, called
directly where Ray Serve would call them through its handles."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

from fastapi.testclient import TestClient

from app.cluster.ingress import ingress_app
from app.cluster.shard import ShardServer
from app.settings import Settings


@contextmanager
def sharded_client(settings: Settings, n_shards: int = 2) -> Iterator[TestClient]:
    """A client of the ingress over ``n_shards`` in-process shards (lifespan included)."""
    servers = [ShardServer(settings, i) for i in range(n_shards)]

    async def call(shard: int, method: str, *args: Any) -> Any:
        return await getattr(servers[shard], method)(*args)

    try:
        with TestClient(ingress_app(settings, n_shards, call)) as client:
            client.app.state.shards = servers  # type: ignore[attr-defined]
            yield client
    finally:
        for server in servers:
            server.close()
