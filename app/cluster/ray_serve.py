"""The sharded service on Ray Serve: one ingress deployment and one deployment a shard.

Each shard is a deployment of one replica (one writer per model); Serve restarts a replica
that dies, and the new one loads its models from their files. ``python -m app serve-ray``
starts a local Ray instance, or joins an existing cluster with ``--ray-address auto`` (on a
cluster, ``--data-dir`` must be a path every node reaches, such as a shared file system).
"""

from __future__ import annotations

import logging
import signal
import threading
from collections.abc import AsyncIterator
from typing import Any

import ray
from ray import serve
from ray.serve.handle import DeploymentHandle

from app.cluster.ingress import ingress_app
from app.cluster.placement import check_shards
from app.cluster.shard import ShardServer
from app.core import compiled
from app.settings import ClusterSettings, Settings

log = logging.getLogger("app.cluster")
APP_NAME = "efsm-shield"
CONCURRENCY = 1000  # requests a replica takes at once; a shard steps one model at a time


class Shard(ShardServer):
    """A shard as a Serve replica; its models are snapshotted when Serve stops it."""

    def __init__(self, settings: Settings, index: int) -> None:
        compiled.warm()  # load the compiled core now, not at the first step
        self._peers: dict[int, DeploymentHandle[Any]] = {}
        super().__init__(settings, index, self._peer)

    async def _peer(self, shard: int, method: str, *args: Any) -> Any:
        if shard not in self._peers:
            self._peers[shard] = serve.get_deployment_handle(f"shard-{shard}", APP_NAME)
        return await getattr(self._peers[shard], method).remote(*args)

    def __del__(self) -> None:
        self.close()


class Ingress:
    """The HTTP and WebSocket contract of the service, over the shards' handles; it holds
    nothing others must share, so Serve may run several."""

    def __init__(self, settings: Settings, *shards: DeploymentHandle[Any]) -> None:
        self._shards = shards
        self._asgi = ingress_app(settings, len(shards), self._call, self._stream)

    async def _call(self, shard: int, method: str, *args: Any) -> Any:
        return await getattr(self._shards[shard], method).remote(*args)

    def _stream(self, shard: int, method: str, *args: Any) -> AsyncIterator[Any]:
        parts: AsyncIterator[Any] = getattr(
            self._shards[shard].options(stream=True), method
        ).remote(*args)
        return parts

    def __serve_build_asgi_app__(self) -> Any:
        return self._asgi


SHARD = serve.deployment(
    ray_actor_options={"num_cpus": 0},
    max_ongoing_requests=CONCURRENCY,
    health_check_period_s=1,
    health_check_timeout_s=30,
)(Shard)
INGRESS = serve.deployment(ray_actor_options={"num_cpus": 0}, max_ongoing_requests=CONCURRENCY)(
    serve.ingress()(Ingress)
)


def application(settings: ClusterSettings) -> Any:
    """The Serve application: ``settings.ingresses`` ingresses over ``settings.shards``
    shards."""
    shards = [SHARD.options(name=f"shard-{i}").bind(settings, i) for i in range(settings.shards)]
    return INGRESS.options(num_replicas=settings.ingresses).bind(settings, *shards)


def run(settings: ClusterSettings) -> None:
    """Start (or join) Ray, deploy the service, and serve until SIGINT or SIGTERM; a data
    directory written for another number of shards is refused first
    (:class:`~app.cluster.placement.PlacementError`)."""
    check_shards(settings.data_dir, settings.shards)  # a wrong shard count fails here
    if settings.ray_address is None:
        ray.init(
            include_dashboard=False,
            num_cpus=settings.ray_cpus,
            object_store_memory=settings.ray_object_store_mb * 2**20,
        )
    else:
        ray.init(address=settings.ray_address)
    stop = threading.Event()
    for signum in (signal.SIGINT, signal.SIGTERM):  # after ray.init, which sets its own
        signal.signal(signum, lambda *_: stop.set())
    try:
        serve.start(http_options={"host": settings.host, "port": settings.port})
        serve.run(application(settings), name=APP_NAME, route_prefix="/")
        log.info(
            "serving on http://%s:%d: %d shards, %d ingresses",
            settings.host,
            settings.port,
            settings.shards,
            settings.ingresses,
        )
        stop.wait()
    finally:
        log.info("stopping: the shards snapshot their models")
        serve.delete(APP_NAME)
        if settings.ray_address is None:
            serve.shutdown()  # type: ignore[no-untyped-call]
        ray.shutdown()
