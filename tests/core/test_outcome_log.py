"""The outcome log: the risk reviser's counts follow the states as eTS+ moves and splits them."""

from __future__ import annotations

import collections
import threading
import time

import numpy as np
import pytest

from app.core import InvalidConfig, InvalidSnapshot, Shield, ShieldConfig
from app.core.belief import recognise
from app.core.outcome_log import OutcomeLog
from tests.core.test_risk import crash_world
from tests.utils import assert_same, random_stream

COUNTS = {"risk": {"model": "counts", "horizon": 8}}  # the model that keeps the log


def counted(**sections: dict[str, object]) -> Shield:
    """A shield of the counted risk model, with ``sections`` merged into its configuration."""
    return Shield(ShieldConfig.from_dict({**COUNTS, **sections}))


def drive(shield: Shield, steps: int, seed: int) -> None:
    """Random steps whose episodes end in a collision now and then."""
    for t, (z, a, done) in enumerate(random_stream(seed, steps)):
        event = "collision" if done and t % 3 == 0 else None
        shield.step(z, None if done else a, done=done, event=event)


def by_hand(shield: Shield) -> tuple[np.ndarray, np.ndarray, dict[tuple[int, int], int]]:
    """The logged transitions counted one by one under each state a step would recognise now
    (the base added), through the public recognition."""
    log = shield.snapshot()["outcome_log"]
    base = log["base"]
    tries, failures = base["tries"].copy(), base["failures"].copy()
    q = shield.config.action.n_bins
    moves = collections.Counter({(int(r), int(c)): int(m) for r, c, m in
                                 zip(base["rows"], base["cols"], base["moves"], strict=True)})

    def state(z: np.ndarray) -> int:
        return recognise(shield.clusterer.sq_distances(z), shield.clusterer.variances(),
                         shield.n_states).argmax()

    for before, after, b, outcome in zip(log["before"], log["after"], log["bins"],
                                         log["outcomes"], strict=True):
        s = state(before)
        tries[s, b] += 1
        if outcome >= 0:
            failures[s, b, outcome] += 1
        else:
            moves[(s * q + int(b), state(after))] += 1
    return tries, failures, dict(moves)


def test_a_recount_counts_every_transition_under_the_states_recognised_now() -> None:
    shield = counted()
    drive(shield, 3000, seed=1)
    assert len(shield.outcome_log) > 0 and shield.outcomes.any_failure
    recounted = shield.outcome_log.recount(shield.clusterer.most_likely, shield.outcomes.version)
    tries, failures, moves = by_hand(shield)
    assert np.array_equal(recounted.tries, tries)
    assert np.array_equal(recounted.failures, failures)
    rows, cols, counts = recounted.moves()
    q_moves = {(int(r), int(c)): int(m) for r, c, m in zip(rows, cols, counts, strict=True)}
    assert q_moves == moves
    assert recounted.tries.sum() == shield.outcomes.tries.sum()  # nothing lost or added


def test_a_recount_of_interleaved_streams_counts_every_transition_alike() -> None:
    # two streams alternate, so a transition's next row is mostly the other stream's: the
    # observations after are recognised afresh rather than taken from the next row
    shield = counted()
    for t, ((z, a, done), (w, b, ended)) in enumerate(zip(random_stream(1, 3000),
                                                          random_stream(2, 3000),
                                                          strict=True)):
        shield.step(z, None if done else a, stream="one", done=done,
                    event="collision" if done and t % 2 == 0 else None)
        shield.step(w, None if ended else b, stream="two", done=ended)
    recounted = shield.outcome_log.recount(shield.clusterer.most_likely, shield.outcomes.version)
    tries, failures, moves = by_hand(shield)
    assert np.array_equal(recounted.tries, tries)
    assert np.array_equal(recounted.failures, failures)
    rows, cols, counts = recounted.moves()
    assert {(int(r), int(c)): int(m) for r, c, m in zip(rows, cols, counts, strict=True)} == moves


def test_recognising_a_large_log_lets_other_threads_run() -> None:
    # a recount of a large model takes seconds; the threads of other models must go on
    clusterer = Shield(ShieldConfig()).clusterer
    rng = np.random.default_rng(0)
    for z in rng.uniform(0, 1, (3000, 3)):
        clusterer.learn_one(z)
    points = rng.uniform(0, 1, (1_000_000, 3))
    clusterer.most_likely(points[:10])  # compiled
    started, done = threading.Event(), threading.Event()

    def recognise_all() -> None:
        started.set()
        clusterer.most_likely(points)
        done.set()

    worker = threading.Thread(target=recognise_all)
    worker.start()
    started.wait()
    time.sleep(0.01)  # the worker is in the kernel: with the GIL held, nothing runs here
    progress = 0
    while not done.is_set():
        progress += 1
    worker.join()
    assert progress > 10_000, progress


def test_a_failure_moves_with_the_states_when_they_are_split() -> None:
    """A crash at x = 0.6 counted when one state covered everything stays on state 0 until a
    recount, which finds it where the states recognise x = 0.6 now."""
    log = OutcomeLog(dim=1, n_actions=3, n_criteria=1, max_states=10, capacity=100)
    for _ in range(2):
        log.add_state()
    log.append(np.array([0.1]), 0, np.array([0.2]), None)
    log.append(np.array([0.2]), 1, np.array([0.6]), None)
    log.append(np.array([0.6]), 2, None, 0)

    def one_state(points: np.ndarray) -> np.ndarray:
        return np.zeros(len(points), dtype=np.int64)

    def split_at_half(points: np.ndarray) -> np.ndarray:
        return (points[:, 0] > 0.5).astype(np.int64)

    before = log.recount(one_state, version=3)
    assert before.failures[:, :, 0].tolist() == [[0, 0, 1], [0, 0, 0]]
    after = log.recount(split_at_half, version=3)
    assert after.failures[:, :, 0].tolist() == [[0, 0, 0], [0, 0, 1]]
    assert after.tries.tolist() == [[1, 1, 0], [0, 0, 1]]
    rows, cols, moves = after.moves()
    assert list(zip(rows.tolist(), cols.tolist(), moves.tolist(), strict=True)) == [
        (0, 0, 1), (1, 1, 1)]


@pytest.mark.parametrize("capacity", [1, 500])
def test_a_full_log_folds_its_older_half_into_the_base(capacity: int) -> None:
    shield = counted(limits={"outcome_log": capacity})
    drive(shield, 4000, seed=2)
    log = shield.outcome_log
    assert 0 < len(log) <= capacity
    Shield.from_snapshot(shield.snapshot())
    assert log.base.tries.sum() + len(log) == shield.outcomes.tries.sum()
    assert log.base.failures.sum() + log.n_failures == shield.outcomes.failures.sum()


def test_without_a_log_the_counts_are_never_redone() -> None:
    logged = counted()
    unlogged = counted(limits={"outcome_log": 0})
    drive(logged, 3000, seed=3)
    drive(unlogged, 3000, seed=3)
    assert len(unlogged.outcome_log) == 0 and unlogged.outcome_log.base.tries.sum() == 0
    assert unlogged.outcomes.tries.sum() == logged.outcomes.tries.sum()


def test_the_log_round_trips_and_the_restored_model_decides_alike() -> None:
    shield = counted(reviser={"activate_after_episodes": 5})
    crash_world(shield, 40, seed=6)
    shield.step([12.0, 20.0, 10.0], 0.5, stream="open")  # a stream mid-episode
    restored = Shield.from_snapshot(shield.snapshot())
    assert_same(restored.snapshot(), shield.snapshot())
    crash_world(shield, 40, seed=7)
    crash_world(restored, 40, seed=7)
    assert_same(restored.snapshot(), shield.snapshot())


def test_a_snapshot_from_before_the_log_keeps_its_counts_where_they_are() -> None:
    shield = counted()
    crash_world(shield, 20, seed=8)
    old = shield.snapshot()
    del old["outcome_log"]
    for stream in old["streams"].values():
        del stream["z"]
    restored = Shield.from_snapshot(old)
    assert np.array_equal(restored.outcome_log.base.tries, shield.outcomes.tries)
    assert len(restored.outcome_log) == 0
    crash_world(restored, 20, seed=9)
    log = restored.outcome_log
    assert log.base.tries.sum() + len(log) == restored.outcomes.tries.sum()


@pytest.mark.parametrize("damage", ["bins", "outcomes", "before", "sums", "size"])
def test_a_damaged_log_is_refused_naming_its_part(damage: str) -> None:
    shield = counted(limits={"outcome_log": 5000})
    drive(shield, 1500, seed=10)
    data = shield.snapshot()
    log = data["outcome_log"]
    field = f"outcome_log.{damage}"
    if damage == "bins":
        log["bins"] = log["bins"] + 20
    elif damage == "outcomes":
        log["outcomes"] = log["outcomes"] - 1
    elif damage == "before":
        log["before"] = log["before"][:, :2]
    elif damage == "sums":
        log["bins"], log["outcomes"] = log["bins"][1:], log["outcomes"][1:]
        log["before"], log["after"] = log["before"][1:], log["after"][1:]
        field = "outcome_log"
    else:
        data["config"]["limits"]["outcome_log"] = 10
        field = "outcome_log.bins"
    with pytest.raises(InvalidSnapshot) as refused:
        Shield.from_snapshot(data)
    assert refused.value.field == field


def test_a_bad_log_bound_names_its_field() -> None:
    with pytest.raises(InvalidConfig) as refused:
        ShieldConfig.from_dict({"limits": {"outcome_log": -1}})
    assert refused.value.field == "limits.outcome_log"


def test_the_default_acts_from_the_first_episodes_and_the_paper_waits_fifty() -> None:
    default, paper = Shield(), Shield(ShieldConfig.paper())
    assert crash_world(default, 3, seed=1) > 0 and crash_world(paper, 3, seed=1) > 0
    assert default.step([28.0, 20.0, 10.0], 1.9).reason != "inactive"
    assert paper.step([28.0, 20.0, 10.0], 1.9).reason == "inactive"
