"""A step sent again with its idempotency key is applied once and answered with its first
decision, across snapshots and crashes; the window of remembered keys is bounded (issue #69,
finding 8)."""

from __future__ import annotations

from pathlib import Path

import pytest

from app.core import ShieldConfig
from app.service.idempotency import KeyReused, TooManyKeys
from app.service.registry import ModelRegistry, Step
from tests.utils import random_stream


def keyed_steps(seed: int, n: int, prefix: str = "k") -> list[Step]:
    return [
        Step(z, None if done else a, done=done, key=f"{prefix}{i}")
        for i, (z, a, done) in enumerate(random_stream(seed, n))
    ]


def reopen(data: Path, **kwargs: object) -> ModelRegistry:
    """A registry over ``data``; the one before it is abandoned unclosed, as by a kill -9."""
    registry = ModelRegistry(data, fsync="always", **kwargs)  # type: ignore[arg-type]
    registry.open()
    return registry


def version(registry: ModelRegistry) -> int:
    return registry.get("default").shield.counters.model_version


def test_a_step_sent_again_is_answered_with_its_first_decision() -> None:
    registry = ModelRegistry()
    registry.open()
    steps = keyed_steps(1, 30)
    first = [registry.step("default", s) for s in steps]
    again = [registry.step("default", s) for s in steps[-5:]]
    assert again == first[-5:]
    assert version(registry) == 30
    unkeyed = Step(steps[0].observation, steps[0].action)
    registry.step("default", unkeyed)
    registry.step("default", unkeyed)  # without a key, every send is a step
    assert version(registry) == 32


def test_a_key_sent_with_another_step_is_refused_and_changes_nothing() -> None:
    registry = ModelRegistry()
    registry.open()
    registry.step("default", Step([10.0, 50.0, 12.0], 0.5, key="a"))
    for other in (
        Step([10.0, 50.0, 12.0], 0.4, key="a"),
        Step([10.0, 50.0, 12.0], 0.5, stream="car-2", key="a"),
        Step([10.0, 50.0, 12.0], 0.5, learn=False, key="a"),
    ):
        with pytest.raises(KeyReused) as refused:
            registry.step("default", other)
        assert refused.value.field == "idempotency_key"
    with pytest.raises(KeyReused) as refused:
        registry.step_batch(
            "default", [Step([1.0, 2.0, 3.0], 0.1, key="b"), Step([1.0, 2.0, 3.0], 0.1, key="b")]
        )
    assert refused.value.field == "steps.1.idempotency_key"
    assert version(registry) == 1


def test_a_batch_sent_again_is_answered_in_full_and_mixed_with_new_steps() -> None:
    registry = ModelRegistry()
    registry.open()
    steps = keyed_steps(2, 20)
    first = registry.step_batch("default", steps[:10])
    mixed = registry.step_batch("default", steps[5:15])  # 5 known, 5 new
    assert mixed[:5] == first[5:]
    assert [d.model_version for d in mixed[5:]] == list(range(11, 16))
    assert version(registry) == 15


def test_the_window_is_bounded_and_a_request_never_outgrows_it() -> None:
    registry = ModelRegistry(idempotency_window=4)
    registry.open()
    steps = keyed_steps(3, 6)
    for s in steps:
        registry.step("default", s)
    model = registry.get("default")
    assert len(model.keys) == 4
    registry.step("default", steps[-1])
    assert version(registry) == 6  # remembered
    registry.step("default", steps[0])
    assert version(registry) == 7  # forgotten: beyond the window, a step like any other
    with pytest.raises(TooManyKeys) as refused:
        registry.step_batch("default", keyed_steps(4, 5, "x"))
    assert refused.value.field == "steps"
    assert version(registry) == 7


@pytest.mark.parametrize("snapshot_every", [10**6, 7])
def test_a_step_applied_and_unanswered_at_a_crash_is_answered_once_after_it(
    tmp_path: Path, snapshot_every: int
) -> None:
    """A kill -9 between the apply and the answer: the retry finds the key in the journal
    (or, once a snapshot has covered the step, in the window the new journal starts with)."""
    first = reopen(tmp_path, snapshot_every=snapshot_every)
    steps = keyed_steps(5, 40)
    decisions = [first.step("default", s) for s in steps]  # the last answers are 'lost'
    second = reopen(tmp_path, snapshot_every=snapshot_every)
    assert [second.step("default", s) for s in steps[-12:]] == decisions[-12:]
    assert version(second) == 40
    assert second.step_batch("default", steps[-3:]) == decisions[-3:]
    third = reopen(tmp_path, snapshot_every=snapshot_every)  # and again, after the retries
    assert third.step("default", steps[-1]) == decisions[-1]
    assert version(third) == 40


def test_a_model_moved_or_restored_with_its_keys_remembers_them(tmp_path: Path) -> None:
    source = reopen(tmp_path / "a")
    source.create("m", ShieldConfig())
    steps = keyed_steps(6, 10)
    decisions = [source.step("m", s) for s in steps]
    model = source.get("m")
    target = reopen(tmp_path / "b")
    target.restore("m", model.shield.snapshot(), model.keys.entries())
    assert target.step("m", steps[-1]) == decisions[-1]
    assert reopen(tmp_path / "b").step("m", steps[-2]) == decisions[-2]
    assert reopen(tmp_path / "b").get("m").shield.counters.model_version == 10
