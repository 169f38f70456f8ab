"""The registry and its files: replay rebuilds the same model; damage is survived."""

from __future__ import annotations

import logging
import threading
import time
from pathlib import Path

import pytest

from app.core import Shield, ShieldConfig
from app.service.registry import Model, ModelRegistry, Step, UnknownModel
from tests.utils import assert_same, random_stream


def feed(registry: ModelRegistry, name: str, seed: int, n: int) -> None:
    for z, a, done in random_stream(seed, n):
        registry.step(name, Step(z, None if done else a, done=done))


def reopen(data: Path, **kwargs: object) -> ModelRegistry:
    registry = ModelRegistry(data, fsync="always", **kwargs)  # type: ignore[arg-type]
    registry.open()
    return registry


def test_journal_replay_rebuilds_the_identical_model(tmp_path: Path) -> None:
    first = reopen(tmp_path)
    feed(first, "default", 0, 120)
    expected = first.get("default").shield.snapshot()
    # no close(): as after a crash, only the journal has the steps
    second = reopen(tmp_path)
    assert_same(second.get("default").shield.snapshot(), expected)


def test_snapshot_plus_journal_tail(tmp_path: Path) -> None:
    first = reopen(tmp_path, snapshot_every=50)
    feed(first, "default", 1, 130)
    assert (tmp_path / "models/default/snapshot.npz").exists()
    expected = first.get("default").shield.snapshot()
    second = reopen(tmp_path)
    assert_same(second.get("default").shield.snapshot(), expected)
    # and the restored model keeps deciding like the original
    feed(first, "default", 2, 40)
    feed(second, "default", 2, 40)
    assert_same(second.get("default").shield.snapshot(), first.get("default").shield.snapshot())


def test_a_torn_last_record_is_cut_off_kept_beside_the_journal_and_logged(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    first = reopen(tmp_path)
    feed(first, "default", 3, 30)
    version = first.get("default").shield.counters.model_version
    journal = tmp_path / "models/default/journal.log"
    with open(journal, "ab") as f:
        f.write(b'0badc0de {"v": 31, "steps": [{"o": [1')  # a crash mid-write
    with caplog.at_level(logging.WARNING):
        second = reopen(tmp_path)
    assert second.get("default").shield.counters.model_version == version
    assert "model 'default' repaired: journal.log line 31" in caplog.text
    (kept,) = journal.parent.glob("journal.log.damaged-*")
    assert kept.read_bytes() == b'0badc0de {"v": 31, "steps": [{"o": [1'


def test_models_survive_a_clean_restart_and_deletion_removes_files(tmp_path: Path) -> None:
    first = reopen(tmp_path)
    first.create("run-1", ShieldConfig.from_dict({"reviser": {"seed": 4}}))
    feed(first, "run-1", 4, 60)
    first.close()
    second = reopen(tmp_path)
    assert second.names() == ["default", "run-1"]
    assert second.get("run-1").shield.config.reviser.seed == 4
    assert second.get("run-1").shield.counters.steps == 60
    second.delete("run-1")
    assert not (tmp_path / "models/run-1").exists()


def test_concurrent_streams_on_one_model_lose_no_update() -> None:
    registry = ModelRegistry()
    registry.open()
    errors: list[BaseException] = []

    def stream(i: int) -> None:
        try:
            for z, a, done in random_stream(i, 100):
                registry.step("default", Step(z, None if done else a, stream=f"s{i}", done=done))
        except BaseException as error:  # pragma: no cover - reported below
            errors.append(error)

    threads = [threading.Thread(target=stream, args=(i,)) for i in range(16)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors
    counters = registry.get("default").shield.counters
    assert counters.steps == counters.model_version == 1600
    assert counters.episodes == 16 * 4


def test_a_step_waiting_on_a_replaced_model_is_refused(tmp_path: Path) -> None:
    registry = reopen(tmp_path)
    old = registry.get("default")
    outcome: list[BaseException | None] = []

    def step() -> None:
        try:
            registry.step("default", Step([1.0, 2.0, 3.0], 0.0))
            outcome.append(None)
        except BaseException as error:
            outcome.append(error)

    with old.lock:  # a step of another thread looks the model up, then waits here ...
        waiting = threading.Thread(target=step)
        waiting.start()
        time.sleep(0.3)
        # ... while a PUT swaps in a new model under the same name
        registry._models["default"] = Model("default", Shield(), None)
    waiting.join()
    assert isinstance(outcome[0], UnknownModel)
    assert old.shield.counters.model_version == 0  # nothing applied to the retired model
