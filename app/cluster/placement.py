"""Which shard owns a model: rendezvous hashing of its name, and a table of the models moved.

Rendezvous (highest random weight) hashing gives every name a fixed shard without a central
table, and a name's owner never depends on which other models exist. A model moved to another
shard (to rebalance a cluster) is recorded in the table, which is stored beside the shards'
data, so that an ingress that restarts routes it where its files are.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

from app.settings import Settings


class PlacementError(ValueError):
    """A placement file that does not fit the cluster it was read for."""


class Placement:
    """The owner shard of every model name among ``n_shards`` shards."""

    def __init__(self, n_shards: int, path: Path | None = None) -> None:
        if n_shards < 1:
            raise PlacementError("a cluster has at least one shard")
        self.n_shards = n_shards
        self.path = path
        self.moved: dict[str, int] = {}
        if path is not None:
            if path.exists():
                self._load(path)
            else:
                self._save()  # the shard count is recorded from the first start on

    def owner(self, name: str) -> int:
        """The shard that owns ``name``: where it was moved, else its highest-weight shard."""
        moved = self.moved.get(name)
        return moved if moved is not None else hashed_owner(name, self.n_shards)

    def move(self, name: str, shard: int) -> None:
        """Record that ``name`` now lives on ``shard`` (and store the table)."""
        if not 0 <= shard < self.n_shards:
            raise PlacementError(f"shard {shard} is not among the {self.n_shards} shards")
        if shard == hashed_owner(name, self.n_shards):
            self.moved.pop(name, None)
        else:
            self.moved[name] = shard
        self._save()

    def forget(self, name: str) -> None:
        """A deleted model goes back to its hashed owner (for a model of that name later)."""
        if self.moved.pop(name, None) is not None:
            self._save()

    def _load(self, path: Path) -> None:
        try:
            data = json.loads(path.read_text())
        except ValueError as error:
            raise PlacementError(f"{path} is unreadable: {error}") from error
        if not isinstance(data, dict):
            raise PlacementError(f"{path} does not hold a placement")
        if data.get("shards") != self.n_shards:
            raise PlacementError(
                f"{path} was written for {data.get('shards')} shards, not {self.n_shards}: a "
                "cluster's models stay on the shards that hold their files; start it with the "
                "same number of shards")
        moved = data.get("moved", {})
        if not isinstance(moved, dict) or not all(
                isinstance(k, str) and isinstance(v, int) and 0 <= v < self.n_shards
                for k, v in moved.items()):
            raise PlacementError(f"{path}: 'moved' must map names to shard indices")
        self.moved = dict(moved)

    def _save(self) -> None:
        if self.path is None:
            return
        self.path.parent.mkdir(parents=True, exist_ok=True)
        temporary = self.path.with_suffix(".tmp")
        with open(temporary, "w") as file:
            json.dump({"shards": self.n_shards, "moved": self.moved}, file, sort_keys=True)
            file.flush()
            os.fsync(file.fileno())
        os.replace(temporary, self.path)


def placement_path(settings: Settings) -> Path | None:
    """Where a cluster with these settings keeps its placement (None: in memory only)."""
    return None if settings.data_dir is None else settings.data_dir / "placement.json"


def hashed_owner(name: str, n_shards: int) -> int:
    """The shard of highest weight ``blake2b(shard, name)`` for ``name``: stable across
    processes and machines, and adding a shard moves only the names it wins."""
    def weight(shard: int) -> bytes:
        return hashlib.blake2b(f"{shard}\0{name}".encode(), digest_size=8).digest()
    return max(range(n_shards), key=weight)
