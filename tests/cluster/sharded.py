"""The sharded service in one process: ingresses over :class:`ShardServer` objects, called
directly where Ray Serve would call them through its handles."""

from __future__ import annotations

from collections.abc import AsyncIterator, Iterator
from contextlib import ExitStack, contextmanager
from typing import Any

from fastapi.testclient import TestClient

from app.cluster.ingress import ingress_app
from app.cluster.shard import ShardServer
from app.settings import Settings


@contextmanager
def sharded_clients(
    settings: Settings, n_shards: int = 2, n_ingresses: int = 1
) -> Iterator[tuple[list[TestClient], list[ShardServer]]]:
    """Clients of ``n_ingresses`` ingresses over the same ``n_shards`` in-process shards."""
    servers: list[ShardServer] = []

    async def call(shard: int, method: str, *args: Any) -> Any:
        return await getattr(servers[shard], method)(*args)

    def stream(shard: int, method: str, *args: Any) -> AsyncIterator[Any]:
        parts: AsyncIterator[Any] = getattr(servers[shard], method)(*args)
        return parts

    servers.extend(ShardServer(settings, i, call) for i in range(n_shards))
    try:
        with ExitStack() as stack:
            apps = [ingress_app(settings, n_shards, call, stream) for _ in range(n_ingresses)]
            clients = [stack.enter_context(TestClient(app)) for app in apps]
            yield clients, servers
    finally:
        for server in servers:
            server.close()


@contextmanager
def sharded_client(settings: Settings, n_shards: int = 2) -> Iterator[TestClient]:
    """A client of one ingress over ``n_shards`` in-process shards (lifespan included)."""
    with sharded_clients(settings, n_shards) as (clients, _):
        yield clients[0]
