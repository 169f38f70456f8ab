"""Which shard owns a model: rendezvous hashing, the table of moved models, its file."""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path

import pytest

from app.cluster.placement import Placement, PlacementError, hashed_owner

NAMES = [f"car-{i}" for i in range(2000)]


def test_owners_are_stable_and_spread_evenly() -> None:
    owners = [hashed_owner(name, 4) for name in NAMES]
    assert owners == [hashed_owner(name, 4) for name in NAMES]
    assert hashed_owner("default", 4) == 2  # fixed across processes and machines (no salt)
    counts = Counter(owners)
    assert set(counts) == {0, 1, 2, 3} and min(counts.values()) > 400  # 500 each expected


def test_adding_a_shard_moves_only_the_names_it_wins() -> None:
    before = {name: hashed_owner(name, 4) for name in NAMES}
    after = {name: hashed_owner(name, 5) for name in NAMES}
    moved = [name for name in NAMES if before[name] != after[name]]
    assert all(after[name] == 4 for name in moved)
    assert 300 < len(moved) < 500  # about a fifth


def test_moves_are_stored_and_read_back(tmp_path: Path) -> None:
    path = tmp_path / "placement.json"
    placement = Placement(3, path)
    assert json.loads(path.read_text()) == {"moved": {}, "shards": 3}  # the count, from the start
    name = NAMES[0]
    target = (hashed_owner(name, 3) + 1) % 3
    placement.move(name, target)
    assert Placement(3, path).owner(name) == target
    placement.move(name, hashed_owner(name, 3))  # back home: no entry left
    assert Placement(3, path).moved == {}
    placement.move(name, target)
    placement.forget(name)
    assert Placement(3, path).owner(name) == hashed_owner(name, 3)


def test_a_placement_file_of_another_cluster_or_damaged_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "placement.json"
    Placement(2, path)
    with pytest.raises(PlacementError, match="written for 2 shards, not 3"):
        Placement(3, path)
    path.write_text(json.dumps({"shards": 2, "moved": {"a": 7}}))
    with pytest.raises(PlacementError, match="'moved' must map names to shard indices"):
        Placement(2, path)
    path.write_text("{not json")
    with pytest.raises(PlacementError, match="unreadable"):
        Placement(2, path)
    with pytest.raises(PlacementError, match="not among"):
        Placement(2).move("a", 2)
    with pytest.raises(PlacementError, match="at least one shard"):
        Placement(0)
