"""Which shard owns a model: rendezvous hashing of its name, and the moves that override it.

Every name has a home shard, the one of highest rendezvous weight: the same on every process
and machine, with no table to share, and a new shard takes only the names it wins. A model
moved away leaves a forwarding entry on the shard it left (:class:`Moves` with a file, one per
shard), so a request that reaches that shard learns where the model went; an ingress keeps
what it learned in memory (:class:`Moves` without a file). So any number of ingresses route
alike without sharing anything but the shards.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path


class PlacementError(ValueError):
    """A cluster's data directory that does not fit the cluster started on it."""


class Moves:
    """Models that are not on their home shard: name -> the shard they went to."""

    def __init__(self, path: Path | None = None) -> None:
        self.path = path
        self.where: dict[str, int] = {}
        if path is not None and path.exists():
            try:
                where = json.loads(path.read_text())
            except ValueError as error:
                raise PlacementError(f"{path} is unreadable: {error}") from error
            if not isinstance(where, dict) or not all(
                isinstance(k, str) and isinstance(v, int) and v >= 0 for k, v in where.items()
            ):
                raise PlacementError(f"{path} must map model names to shard indices")
            self.where = where

    def get(self, name: str) -> int | None:
        """Where ``name`` went, if it moved."""
        return self.where.get(name)

    def set(self, name: str, shard: int) -> None:
        """``name`` is on ``shard`` now (stored at once when there is a file)."""
        if self.where.get(name) != shard:
            self.where[name] = shard
            self._save()

    def discard(self, name: str) -> None:
        """``name`` is back (stored at once when there is a file)."""
        if self.where.pop(name, None) is not None:
            self._save()

    def _save(self) -> None:
        if self.path is None:
            return
        self.path.parent.mkdir(parents=True, exist_ok=True)
        temporary = self.path.with_suffix(".tmp")
        with open(temporary, "w") as file:
            json.dump(self.where, file, sort_keys=True)
            file.flush()
            os.fsync(file.fileno())
        os.replace(temporary, self.path)


def hashed_owner(name: str, n_shards: int) -> int:
    """The home shard of ``name``: the highest weight ``blake2b(shard, name)``."""

    def weight(shard: int) -> bytes:
        return hashlib.blake2b(f"{shard}\0{name}".encode(), digest_size=8).digest()

    return max(range(n_shards), key=weight)


def check_shards(data_dir: Path | None, n_shards: int) -> None:
    """Refuse a data directory written by a cluster of another size (its models' home shards
    would change); record the size on the first start."""
    if n_shards < 1:
        raise PlacementError("a cluster has at least one shard")
    if data_dir is None:
        return
    path = data_dir / "cluster.json"
    if path.exists():
        try:
            written = json.loads(path.read_text()).get("shards")
        except (ValueError, AttributeError) as error:
            raise PlacementError(f"{path} is unreadable: {error}") from error
        if written != n_shards:
            raise PlacementError(
                f"{data_dir} holds a cluster of {written} shards, not {n_shards}: its models "
                "stay on the shards that hold their files; start it with the same number"
            )
        return
    data_dir.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"shards": n_shards}))
