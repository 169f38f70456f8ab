"""A snapshot is written with the model's lock released: steps go on meanwhile, and a crash at
any point of it loses nothing (issue #45)."""

from __future__ import annotations

import threading
from pathlib import Path
from typing import Any

import pytest

from app.service import codec
from app.service.registry import ModelRegistry, Step
from tests.utils import assert_same, random_stream


def steps(seed: int, n: int) -> list[Step]:
    return [Step(z, None if done else a, done=done) for z, a, done in random_stream(seed, n)]


def test_steps_go_on_while_a_snapshot_is_written(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    registry = ModelRegistry(tmp_path, fsync="always", snapshot_every=20)
    registry.open()
    writing, stepped = threading.Event(), threading.Event()
    original = codec.to_npz
    overlapped: list[bool] = []

    def slow(data: dict[str, Any]) -> bytes:
        writing.set()
        overlapped.append(stepped.wait(10))  # other steps finish while this one writes
        return original(data)

    monkeypatch.setattr(codec, "to_npz", slow)  # the module the registry calls
    batch = steps(1, 60)
    writer = threading.Thread(target=lambda: [registry.step("default", s) for s in batch[:20]])
    writer.start()
    assert writing.wait(10)  # the 20th step's snapshot is being compressed
    for step in batch[20:40]:  # the same model steps meanwhile (its snapshot is skipped)
        registry.step("default", step)
    stepped.set()
    writer.join()
    assert overlapped == [True]
    monkeypatch.setattr(codec, "to_npz", original)
    for step in batch[40:]:
        registry.step("default", step)
    expected = registry.get("default").shield.snapshot()
    again = ModelRegistry(tmp_path, fsync="always")  # as after a crash: files only
    again.open()
    assert_same(again.get("default").shield.snapshot(), expected)


def test_a_crash_between_the_rotation_and_the_write_loses_nothing(tmp_path: Path) -> None:
    registry = ModelRegistry(tmp_path, fsync="always", snapshot_every=10**6)
    registry.open()
    for step in steps(2, 50):
        registry.step("default", step)
    model = registry.get("default")
    with model.lock:
        registry._take(model)  # the state copied and the journal rotated, never written
    for step in steps(3, 30):
        registry.step("default", step)
    expected = model.shield.snapshot()
    assert (tmp_path / "models/default/journal.1.log").exists()
    again = ModelRegistry(tmp_path, fsync="always")
    again.open()
    assert_same(again.get("default").shield.snapshot(), expected)
    again.close()  # its snapshot covers both journals and removes the rotated one
    assert not (tmp_path / "models/default/journal.1.log").exists()
    third = ModelRegistry(tmp_path, fsync="always")
    third.open()
    assert_same(third.get("default").shield.snapshot(), expected)
