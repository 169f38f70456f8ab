"""The model's history (app/core/history.py): totals at the end of episodes, bounded, kept
through a snapshot, and refused when a snapshot's rows could not come from a model."""

from __future__ import annotations

import copy
from typing import Any

import numpy as np
import pytest

from app.core import InvalidSnapshot, Shield
from app.core.history import EPISODES, History
from tests.utils import assert_same, cliff_config, run_cliff


def test_each_episode_end_keeps_the_totals_of_that_moment() -> None:
    shield = Shield(cliff_config(activate_after_episodes=3))
    seen = []
    rng = np.random.default_rng(0)
    for episode in range(8):
        for _ in range(5 + episode):
            shield.step([float(rng.uniform(0.3, 0.7))], float(rng.uniform(-2, 2)))
        failed = episode % 3 == 0
        shield.step([0.95], None, done=True, event="collision" if failed else None)
        c = shield.counters
        seen.append(
            (
                c.episodes,
                c.steps,
                shield.n_states,
                c.interventions["collision"],
                c.interventions["large_distance"],
                c.failures["collision"],
                c.failures["large_distance"],
            )
        )
    view = shield.history_view()
    rows = list(
        zip(
            view["episodes"],
            view["steps"],
            view["n_states"],
            view["interventions"]["collision"],
            view["interventions"]["large_distance"],
            view["failures"]["collision"],
            view["failures"]["large_distance"],
            strict=True,
        )
    )
    assert rows == seen
    assert view["failures"]["collision"][-1] == 3  # episodes 0, 3 and 6 failed
    assert view["steps"][:2] == [6, 13]  # 5 steps and the closing one, then 6 and 1 more
    assert view["stride"] == 1 and view["totals"]["episodes"] == 8
    assert sum(shield.counters.interventions.values()) > 0  # the revisions are counted too


def test_a_what_if_step_changes_no_total() -> None:
    shield = Shield(cliff_config())
    shield.step([0.5], 0.0)
    before = shield.history_view()
    shield.step([0.95], None, done=True, event="collision", learn=False)
    assert shield.history_view() == before


def test_a_full_history_halves_and_still_spans_the_whole_life() -> None:
    history = History(n_criteria=0, limit=8)
    for episode in range(1, 101):
        history.record([episode, 10 * episode, 1])
        assert history.rows.shape[0] <= 8
        # the rows stay evenly spaced from the start, one every `stride` episodes
        episodes = history.rows[:, EPISODES]
        assert (episodes == history.stride * np.arange(1, episodes.size + 1)).all()
    assert history.stride == 16 and history.rows[:, EPISODES].tolist() == [16, 32, 48, 64, 80, 96]
    assert history.rows[:, 1].tolist() == [160, 320, 480, 640, 800, 960]  # totals kept


def test_the_history_survives_a_snapshot_and_goes_on_alike() -> None:
    shield = Shield(cliff_config(activate_after_episodes=5))
    run_cliff(shield, 30, seed=4)
    restored = Shield.from_snapshot(shield.snapshot())
    assert restored.history_view() == shield.history_view()
    run_cliff(shield, 20, seed=9)
    run_cliff(restored, 20, seed=9)
    assert restored.history_view() == shield.history_view()
    assert_same(restored.snapshot(), shield.snapshot())
    assert len(shield.history_view()["episodes"]) == 50


def test_a_snapshot_from_before_the_history_starts_it_from_its_totals() -> None:
    shield = Shield(cliff_config())
    failed, _ = run_cliff(shield, 12, seed=1)
    old = shield.snapshot()
    del old["history"], old["counters"]["failures"]
    restored = Shield.from_snapshot(old)
    view = restored.history_view()
    # the failures its states counted, and one row: the totals at the restore
    assert restored.counters.failures["collision"] == sum(failed) > 0
    assert view["episodes"] == [12] and view["steps"] == [shield.counters.steps]
    assert view["failures"]["collision"] == [sum(failed)]


def broken(shield: Shield, change: Any) -> dict[str, Any]:
    data = copy.deepcopy(shield.snapshot())
    change(data["history"])
    return data


def swap_rows(h: dict[str, Any]) -> None:
    h["rows"] = h["rows"][::-1].copy()


def off_stride(h: dict[str, Any]) -> None:
    h["stride"] = 4


def beyond_counters(h: dict[str, Any]) -> None:
    h["rows"][-1, 1] += 1


def too_many_rows(h: dict[str, Any]) -> None:
    h["rows"] = np.repeat(h["rows"][-1:], 513, axis=0)


def wrong_width(h: dict[str, Any]) -> None:
    h["rows"] = h["rows"][:, :3].copy()


@pytest.mark.parametrize(
    "change,field",
    [
        (swap_rows, "history.rows"),
        (off_stride, "history.rows"),
        (beyond_counters, "history.rows"),
        (too_many_rows, "history.rows"),
        (wrong_width, "history.rows"),
        (lambda h: h.update(stride=3), "history.stride"),
        (lambda h: h.update(stride=0), "history.stride"),
    ],
)
def test_a_history_no_model_could_have_is_refused(change: Any, field: str) -> None:
    shield = Shield(cliff_config())
    run_cliff(shield, 6, seed=2)
    with pytest.raises(InvalidSnapshot) as raised:
        Shield.from_snapshot(broken(shield, change))
    assert raised.value.field == field
