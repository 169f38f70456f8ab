"""Which shard owns a model: rendezvous hashing, the moves that override it, and the size of
the cluster a data directory belongs to."""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path

import pytest

from app.cluster.placement import Moves, PlacementError, check_shards, hashed_owner

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
    path = tmp_path / "moved.json"
    moves = Moves(path)
    moves.set("a", 2)
    moves.set("b", 0)
    assert Moves(path).where == {"a": 2, "b": 0}
    moves.discard("a")
    assert Moves(path).get("a") is None and Moves(path).get("b") == 0
    assert Moves().get("b") is None  # in memory only: nothing read


def test_damaged_move_files_are_refused(tmp_path: Path) -> None:
    path = tmp_path / "moved.json"
    path.write_text("{not json")
    with pytest.raises(PlacementError, match="unreadable"):
        Moves(path)
    path.write_text(json.dumps({"a": -1}))
    with pytest.raises(PlacementError, match="must map model names to shard indices"):
        Moves(path)


def test_a_data_directory_of_another_cluster_size_is_refused(tmp_path: Path) -> None:
    check_shards(tmp_path, 2)
    check_shards(tmp_path, 2)  # the same size again: fine
    with pytest.raises(PlacementError, match="holds a cluster of 2 shards, not 3"):
        check_shards(tmp_path, 3)
    (tmp_path / "cluster.json").write_text("[]")
    with pytest.raises(PlacementError, match="unreadable"):
        check_shards(tmp_path, 2)
    with pytest.raises(PlacementError, match="at least one shard"):
        check_shards(None, 0)
