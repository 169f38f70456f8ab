"""One shard: the plain service over a data directory of its own, answering in process what
an ingress forwards, and handing a model to another shard when asked.

A shard that restarts loads its models from their files (snapshots and journals), as ``python
-m app serve`` does. Models it gave away stay recorded (``moved.json``): a request for one gets
:class:`Moved`, which tells the ingress where to send it instead.
"""

from __future__ import annotations

import asyncio
import json
import logging
import os
import socket
from collections import Counter
from collections.abc import AsyncIterator, Awaitable, Callable, Iterable, Sequence
from contextlib import asynccontextmanager
from dataclasses import dataclass
from typing import Any

from app.api.errors import error_body, status_of
from app.api.routes.stream import answer
from app.cluster.asgi import Reply, Request, call, stream
from app.cluster.placement import Moves
from app.cluster.routing import named
from app.core import ShieldError
from app.main import create_app
from app.service import codec
from app.service.idempotency import Entry
from app.service.registry import ModelRegistry
from app.settings import Settings

log = logging.getLogger("app.cluster")

ShardCall = Callable[..., Awaitable[Any]]
"""``call(shard, method, *args)``: run a :class:`ShardServer` method on shard ``shard``."""
ShardStream = Callable[..., AsyncIterator[Any]]
"""``stream(shard, method, *args)``: the parts of a :class:`ShardServer` method that streams."""


@dataclass(frozen=True)
class Moved:
    """Model ``name`` is not here: it was moved to shard ``owner``."""

    name: str
    owner: int


class Gates:
    """Per model: the requests in flight, and a move that waits for them and holds new ones."""

    def __init__(self) -> None:
        self._changed = asyncio.Condition()
        self._busy: Counter[str] = Counter()
        self._moving: set[str] = set()

    @asynccontextmanager
    async def use(self, names: Iterable[str]) -> AsyncIterator[None]:
        """Hold ``names`` where they are while a request about them runs."""
        names = sorted(set(names))
        async with self._changed:
            await self._changed.wait_for(lambda: not self._moving.intersection(names))
            self._busy.update(names)
        try:
            yield
        finally:
            async with self._changed:
                self._busy.subtract(names)
                self._changed.notify_all()

    @asynccontextmanager
    async def exclusive(self, name: str) -> AsyncIterator[None]:
        """Wait until nothing about ``name`` runs, and hold new requests until the end."""
        async with self._changed:
            await self._changed.wait_for(lambda: name not in self._moving)
            self._moving.add(name)
            await self._changed.wait_for(lambda: self._busy[name] == 0)
        try:
            yield
        finally:
            async with self._changed:
                self._moving.discard(name)
                self._changed.notify_all()


def shard_settings(settings: Settings, index: int) -> Settings:
    """The settings of shard ``index``: the cluster's, with ``<data_dir>/shards/<index>``."""
    if settings.data_dir is None:
        return settings
    return settings.model_copy(update={"data_dir": settings.data_dir / "shards" / str(index)})


class ShardServer:
    """The models of one shard, behind the plain service's routes; ``peer`` reaches the
    other shards (a move hands the model over itself)."""

    def __init__(self, settings: Settings, index: int, peer: ShardCall) -> None:
        self.index = index
        self.peer = peer
        own = shard_settings(settings, index)
        self.app = create_app(own, create_default=False)
        self.registry: ModelRegistry = self.app.state.registry
        self.gates = Gates()
        self.moved = Moves(None if own.data_dir is None else own.data_dir / "moved.json")
        self.registry.open()
        for name in set(self.moved.where) & set(self.registry.names()):
            log.warning(
                "shard %d: %r was handed to shard %d before a stop; deleting the copy left here",
                index,
                name,
                self.moved.where[name],
            )
            self.registry.delete(name)  # a move that stopped between its last two steps
        log.info(
            "shard %d (pid %d): %d models loaded", index, os.getpid(), len(self.registry.names())
        )

    def _away(self, names: Iterable[str]) -> Moved | None:
        for name in names:
            owner = self.moved.get(name)
            if owner is not None:
                return Moved(name, owner)
        return None

    async def request(self, request: Request) -> Reply | Moved:
        """An HTTP request of the service's contract, answered by this shard's app."""
        names = named(request.method, request.path, request.body)
        async with self.gates.use(names):
            return self._away(names) or await call(self.app, request)

    async def stream(self, request: Request) -> AsyncIterator[Reply | bytes | Moved]:
        """A streamed answer (the live event feed of a model): its head, then its pieces. A
        stream does not hold its model here; once the model moved away it ends (within the
        feed's 10 s ping), and a reconnecting reader is sent where the model went."""
        names = named(request.method, request.path, request.body)
        if (away := self._away(names)) is not None:
            yield away
            return
        async for part in stream(self.app, request):
            yield part
            if self._away(names) is not None:
                return

    async def frame(self, name: str, text: str) -> str | Moved:
        """One WebSocket frame (a step of model ``name``): the decision record or an error."""
        async with self.gates.use([name]):
            return self._away([name]) or await answer(self.registry, name, text)

    async def refusal(self, name: str) -> dict[str, Any] | Moved | None:
        """The error body that refuses a stream of model ``name``, None if it serves here."""
        if (away := self._away([name])) is not None:
            return away
        try:
            self.registry.get(name)
        except ShieldError as error:
            return error_body(error.code, error.message, "name")
        return None

    async def ensure_default(self) -> Moved | None:
        """Create the 'default' model here (this is its home shard) unless it moved away."""
        away = self._away(["default"])
        if away is None:
            self.registry.ensure_default()
        return away

    async def move(self, name: str, to: int) -> Reply | Moved:
        """Hand model ``name`` to shard ``to``: its requests here wait, its snapshot is
        restored there with the idempotency keys it remembers, this shard records where it
        went and deletes its copy; the requests that waited are then told where it is."""
        async with self.gates.exclusive(name):
            if (away := self._away([name])) is not None:
                return away
            try:
                model = self.registry.get(name)
            except ShieldError as error:
                return _error(error)
            if to != self.index:
                with model.lock:
                    blob = codec.to_npz(model.shield.snapshot())
                    keys = model.keys.entries()
                adopted: Reply = await self.peer(to, "adopt", name, blob, keys)
                if adopted.status != 200:
                    return adopted
                self.moved.set(name, to)  # stored before the copy here goes (see __init__)
                self.registry.delete(name)
                log.info("model %r moved from shard %d to shard %d", name, self.index, to)
        return _json(200, {"model": name, "from": self.index, "to": to})

    async def adopt(self, name: str, blob: bytes, keys: Sequence[Entry] = ()) -> Reply:
        """Take model ``name`` from its snapshot and the idempotency keys it remembers (a move
        to this shard)."""
        try:
            snapshot = codec.from_npz(blob, self.app.state.settings.max_snapshot_bytes)
            self.registry.restore(name, snapshot, keys)
        except ShieldError as error:
            return _error(error)
        self.moved.discard(name)
        return _json(200, {"model": name, "to": self.index})

    async def info(self) -> dict[str, Any]:
        """Where this shard runs, what it holds and what it gave away."""
        return {
            "shard": self.index,
            "host": socket.gethostname(),
            "pid": os.getpid(),
            "ready": self.registry.ready,
            "models": self.registry.names(),
            "moved_away": dict(self.moved.where),
            "quarantined": self.registry.quarantined,
        }

    def close(self) -> None:
        """Snapshot every model and close its files."""
        self.registry.close()


def _json(status: int, body: dict[str, Any]) -> Reply:
    return Reply(status, ((b"content-type", b"application/json"),), json.dumps(body).encode())


def _error(error: ShieldError) -> Reply:
    return _json(status_of(error), error_body(error.code, error.message, error.field))
