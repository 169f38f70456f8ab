"""The shield's own record (:mod:`app.core.record`): outcomes settled per state, backing off
where revisions fail more often than the proposals passed, and its snapshot."""

from __future__ import annotations

import numpy as np
import pytest

from app.core import InvalidSnapshot, Shield, ShieldConfig
from app.core.record import (
    COLUMNS,
    PASSED,
    PASSED_FAILED,
    REVISED,
    REVISED_FAILED,
    REVISED_FAILURES,
    Z_EVERYWHERE,
    Record,
    Z,
    band_of,
    excess,
    pooled_excess,
)
from tests.core.checks import risk_parts
from tests.utils import assert_same


def record_of(states: int, window: int = 4) -> Record:
    record = Record(window)
    for _ in range(states):
        record.add_state()
    return record


def test_a_failure_settles_every_pending_step_as_failed_and_an_old_step_as_not() -> None:
    record = record_of(2)
    for t in range(6):  # window 4: the first two steps age out unfailed
        record.note("a", t % 2, revised=t >= 3, risk=0.0)
    assert record.counts[:, PASSED].tolist() == [1, 1]
    assert record.counts[:, PASSED_FAILED].tolist() == [0, 0]
    record.settle("a", failed=True)
    row0, row1 = record.counts
    assert (row0[PASSED], row0[PASSED_FAILED], row0[REVISED], row0[REVISED_FAILED]) == (2, 1, 1, 1)
    assert (row1[PASSED], row1[REVISED], row1[REVISED_FAILED]) == (1, 2, 2)
    assert row1[REVISED_FAILURES] == 1 and row0[REVISED_FAILURES] == 1  # one event each


def test_an_episode_that_ends_well_settles_its_steps_unfailed_and_streams_apart() -> None:
    record = record_of(1)
    record.note("a", 0, revised=True, risk=0.0)
    record.note("b", 0, revised=True, risk=0.0)
    record.settle("a", failed=False)
    assert record.counts[0, REVISED] == 1 and record.counts[0, REVISED_FAILED] == 0
    record.forget("b")  # an expired stream: unsettled, uncounted
    record.settle("b", failed=True)
    assert record.counts[0, REVISED] == 1


def test_it_backs_off_only_where_revisions_fail_clearly_more_often_than_passes() -> None:
    record = record_of(1, window=1)
    row = record.counts[0]
    row[[REVISED, REVISED_FAILED, PASSED, PASSED_FAILED]] = (40, 20, 400, 20)
    row[REVISED_FAILURES] = 1
    assert not record.backs_off(0)  # one failure after revisions is no evidence
    row[REVISED_FAILURES] = 20
    assert record.backs_off(0)
    row[[PASSED, PASSED_FAILED]] = (40, 20)  # the proposals fail as often: revising is no worse
    assert not record.backs_off(0)
    assert record.backed_off().tolist() == [False]


def test_the_excess_counts_a_window_of_steps_as_one_sample() -> None:
    # the same rates from ten times the steps within ten-step windows: the same evidence
    assert excess(400, 200, 4000, 200, 10) == pytest.approx(
        excess(40, 20, 400, 20, 1), rel=0.01
    )  # (the prior aside)
    assert excess(5, 5, 5, 0, 1) > 0 > excess(5, 0, 5, 5, 1)


def backing_off_shield(episodes: bool = False) -> Shield:
    """A shield whose every revision fails at once, and every proposal passes: a world where
    its model is wrong. (A point that fails whenever the shield changes the action.) Without
    ``episodes`` a failure does not end an episode: the stream goes on after it, and no episode
    ends for the shield's trial of itself to audit (:mod:`app.core.trial`)."""
    shield = Shield(ShieldConfig.from_dict({"risk": {"reach_horizon": 0, "horizon": 4}}))
    rng = np.random.default_rng(0)
    for _ in range(80):
        for t in range(30):
            x = [float(rng.uniform(0, 1)), 5.0, 1.0]
            decision = shield.step(x, float(rng.uniform(-2, 2)))
            if (
                decision.revised
                or t == 10
                and decision.action is not None
                and decision.action > 1.5
            ):
                if episodes:
                    shield.step(x, None, done=True, event="collision")
                else:
                    shield.step(x, 0.0, event="collision")
                break
        else:
            if episodes:
                shield.step([0.5, 5.0, 1.0], None, done=True)
    return shield


def test_a_shield_whose_revisions_fail_backs_off_says_so_and_keeps_its_record() -> None:
    shield = backing_off_shield()
    counts = risk_parts(shield).record.counts
    assert counts[:, REVISED_FAILED].sum() > 0 and risk_parts(shield).record.backed_off().any()
    # the same settled steps, by state and by band of the proposal's predicted risk
    bands = risk_parts(shield).record.bands
    assert np.array_equal(bands.sum(axis=0), counts[:, : PASSED_FAILED + 1].sum(axis=0))
    assert np.count_nonzero(bands.sum(axis=1)) > 1
    backed = [shield.step([float(x), 5.0, 1.0], 2.0, learn=False) for x in np.linspace(0, 1, 21)]
    held = [d for d in backed if d.reason == "backed_off"]
    assert held and all(
        d.action == 2.0 and not d.revised and d.suggested != 2.0 and d.verdict != "ok" for d in held
    )
    restored = Shield.from_snapshot(shield.snapshot())
    assert_same(restored.snapshot()["record"], shield.snapshot()["record"])
    assert np.array_equal(
        risk_parts(restored).record.backed_off(), risk_parts(shield).record.backed_off()
    )


@pytest.mark.parametrize(
    ("change", "field"),
    [
        (lambda r: r["counts"].__setitem__((0, REVISED_FAILED), 10**6), "record.counts"),
        (lambda r: r.__setitem__("counts", r["counts"][:, :2]), "record.counts"),
        (lambda r: r.__setitem__("streams", ["nobody"]), "record.streams"),
        (lambda r: r["states"].__setitem__(slice(None), 10**6), "record.states"),
        (lambda r: r["bands"].__setitem__((0, REVISED_FAILED), 10**6), "record.bands"),
        (lambda r: r["risk_bands"].__setitem__(slice(None), 9), "record.risk_bands"),
        (lambda r: r["bands"].__setitem__((0, PASSED), 10**6), "record.bands"),
    ],
)
def test_a_damaged_record_is_refused_naming_its_field(change: object, field: str) -> None:
    shield = Shield(ShieldConfig())
    for t in range(30):
        shield.step([float(t), 5.0, 1.0], 0.5)  # a pending step or more
    shield.step([1.0, 5.0, 1.0], None, done=True, event="collision")
    for t in range(3):
        shield.step([float(t), 5.0, 1.0], 0.5)
    snapshot = shield.snapshot()
    assert len(COLUMNS) == snapshot["record"]["counts"].shape[1]
    assert snapshot["record"]["streams"] == ["default"] or snapshot["record"]["streams"]
    change(snapshot["record"])  # type: ignore[operator]
    with pytest.raises(InvalidSnapshot) as error:
        Shield.from_snapshot(snapshot)
    assert error.value.field == field


def test_a_snapshot_from_before_the_record_restores_with_nothing_counted() -> None:
    shield = Shield(ShieldConfig())
    for t in range(10):
        shield.step([float(t), 5.0, 1.0], 0.5)
    snapshot = shield.snapshot()
    del snapshot["record"]
    restored = Shield.from_snapshot(snapshot)
    assert risk_parts(restored).record.counts.shape == (shield.n_states, len(COLUMNS))
    assert not risk_parts(restored).record.counts.any()


def test_revisions_are_compared_with_passes_of_the_same_predicted_risk_over_all_states() -> None:
    # revisions at high predicted risk fail more often than passes at low risk, but less often
    # than passes at the same risk: they help, and the shield does not back off
    helpful = record_of(2, window=1)
    helpful.bands[band_of(0.0)] = (0, 0, 400, 4)
    helpful.bands[band_of(0.3)] = (200, 40, 100, 60)
    helpful.counts[:, REVISED_FAILURES] = 20
    assert excess(200, 40, 500, 64, 1) > Z  # state-blind, the revisions look worse
    assert pooled_excess(helpful.bands, 1) < 0
    # the same revisions followed by failures more often than passes of their band: harm
    harmful = record_of(2, window=1)
    harmful.bands[band_of(0.3)] = (200, 120, 100, 30)
    assert pooled_excess(harmful.bands, 1) > Z_EVERYWHERE
    assert [band_of(r) for r in (0.0, 0.01, 0.049, 0.2, 0.99)] == [0, 1, 1, 3, 4]


def test_it_backs_off_everywhere_once_settled_steps_show_harm_and_comes_back() -> None:
    record = record_of(3, window=2)
    for episode in range(12):  # revised steps at predicted risk 0.3 fail, passed ones do not
        record.note("a", episode % 3, revised=True, risk=0.3)
        record.settle("a", failed=True)
        record.note("a", episode % 3, revised=False, risk=0.3)
        record.settle("a", failed=False)
    assert record.everywhere and all(record.backs_off(i) for i in range(3))
    restored = Record.restore(2, 3, {"a": 0}, record.snapshot())
    assert restored.everywhere and np.array_equal(restored.bands, record.bands)
    for _ in range(40):  # now the passed proposals fail: revising was better
        record.note("a", 0, revised=False, risk=0.3)
        record.settle("a", failed=True)
    assert not record.everywhere
