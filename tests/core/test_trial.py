"""The shield's trial of itself (:mod:`app.core.trial`): episodes shielded against episodes
audited, drawn by Thompson sampling from discounted counts, and kept in snapshots."""

from __future__ import annotations

import numpy as np
import pytest

from app.core import InvalidSnapshot, Shield, ShieldConfig
from app.core.trial import AUDITED, NONE, SHIELDED, Trial
from tests.core.checks import risk_parts
from tests.core.test_record import backing_off_shield


def harmful_shield() -> Shield:
    """A shield whose every revision fails at once (:func:`backing_off_shield`), in episodes
    that a failure ends."""
    return backing_off_shield(episodes=True)


def audit_share(trial: Trial, draws: int = 2000) -> float:
    return float(np.mean([trial.draw(at) == AUDITED for at in range(draws)]))


def test_a_draw_is_a_function_of_the_seed_and_the_step() -> None:
    trial = Trial(seed=3)
    trial.counts[:] = [[10, 3], [10, 4]]
    assert [trial.draw(at) for at in range(50)] == [trial.draw(at) for at in range(50)]
    other = Trial(seed=4)
    other.counts[:] = trial.counts
    assert [trial.draw(at) for at in range(50)] != [other.draw(at) for at in range(50)]


def test_it_audits_by_how_likely_the_shield_is_the_worse_arm() -> None:
    trial = Trial(seed=0)
    assert 0.4 < audit_share(trial) < 0.6  # no evidence: either arm
    trial.counts[:] = [[40, 2], [10, 5]]  # shielded episodes fail far less often
    assert audit_share(trial) < 0.01
    trial.counts[:] = [[10, 8], [40, 12]]  # shielded episodes fail far more often
    assert audit_share(trial) > 0.99
    trial.counts[:] = [[30, 9], [30, 9]]  # the same: a coin
    assert 0.4 < audit_share(trial) < 0.6


def test_an_episode_counts_in_its_arm_and_one_outside_the_trial_nowhere() -> None:
    trial = Trial(seed=0)
    trial.count(SHIELDED, failed=True)
    trial.count(AUDITED, failed=False)
    trial.count(AUDITED, failed=True)
    trial.count(NONE, failed=True)
    assert trial.view() == {
        "shielded": {"episodes": 1, "failed": 1},
        "audited": {"episodes": 2, "failed": 1},
    }


def test_a_shield_whose_revisions_fail_audits_most_episodes_and_says_so() -> None:
    shield = harmful_shield()
    (shielded, _), (audited, audited_failed) = risk_parts(shield).trial.counts.tolist()
    assert audited > 2 * shielded
    # an audited episode passes every proposal and says what it would have done
    shield.step([0.5, 5.0, 1.0], 2.0, stream="audit-me")
    state = shield.streams["audit-me"]
    state.arm = AUDITED
    decisions = [
        shield.step([float(x), 5.0, 1.0], 2.0, stream="audit-me", learn=False)
        for x in np.linspace(0, 1, 21)
    ]
    audits = [d for d in decisions if d.reason == "audit"]
    assert audits and all(d.action == 2.0 and not d.revised and d.suggested != 2.0 for d in audits)


def test_the_trial_and_each_streams_arm_survive_a_snapshot() -> None:
    shield = harmful_shield()
    for t in range(5):
        shield.step([0.1 * t, 5.0, 1.0], 1.0, stream="open")
    restored = Shield.from_snapshot(shield.snapshot())
    assert np.array_equal(risk_parts(restored).trial.counts, risk_parts(shield).trial.counts)
    assert restored.streams["open"].arm == shield.streams["open"].arm
    rng = np.random.default_rng(1)
    for _ in range(200):  # and both decide the same from here on
        x, a = [float(rng.uniform(0, 1)), 5.0, 1.0], float(rng.uniform(-2, 2))
        assert shield.step(x, a, stream="open") == restored.step(x, a, stream="open")


def test_a_snapshot_from_before_the_trial_restores_with_nothing_counted() -> None:
    shield = harmful_shield()
    snapshot = shield.snapshot()
    del snapshot["trial"]
    for stream in snapshot["streams"].values():
        del stream["arm"], stream["failed"]
    restored = Shield.from_snapshot(snapshot)
    assert not risk_parts(restored).trial.counts.any()
    assert all(s.arm == NONE for s in restored.streams.values())


@pytest.mark.parametrize(
    ("change", "field"),
    [
        (lambda s: s["trial"].__setitem__((0, 1), 10**9), "trial"),
        (lambda s: s["trial"].__setitem__((1, 1), s["trial"][1, 0] + 1), "trial"),
        (lambda s: s.__setitem__("trial", s["trial"].astype(float) + 0.5), "trial"),
        (lambda s: s.__setitem__("trial", s["trial"][:1]), "trial"),
        (lambda s: s["streams"]["open"].__setitem__("arm", 2), "streams.open.arm"),
        (lambda s: s["streams"]["open"].__setitem__("failed", 1), "streams.open.failed"),
    ],
)
def test_a_damaged_trial_is_refused_naming_its_field(change: object, field: str) -> None:
    shield = harmful_shield()
    shield.step([0.5, 5.0, 1.0], 1.0, stream="open")
    snapshot = shield.snapshot()
    change(snapshot)  # type: ignore[operator]
    with pytest.raises(InvalidSnapshot) as error:
        Shield.from_snapshot(snapshot)
    assert error.value.field == field


def test_the_paper_reviser_keeps_no_trial() -> None:
    shield = Shield(ShieldConfig.paper())
    for t in range(40):
        shield.step([float(t % 7), 5.0, 1.0], 0.5)
        if t % 10 == 9:
            shield.step([1.0, 5.0, 1.0], None, done=True, event="collision")
    assert shield.snapshot()["trial"] is None
    assert shield.reviser.trial_view() == {
        arm: {"episodes": 0, "failed": 0} for arm in ("shielded", "audited")
    }


def test_an_audited_episode_counts_in_the_trial_and_stays_out_of_the_record() -> None:
    # the record compares the shield's own steps; an audited episode is the trial's control
    shield = harmful_shield()
    risk_parts(shield).trial.draw = lambda at: AUDITED  # type: ignore[method-assign]
    counts, bands = risk_parts(shield).record.counts.copy(), risk_parts(shield).record.bands.copy()
    trial = risk_parts(shield).trial.counts.copy()
    reasons = {shield.step([0.1 * t, 5.0, 1.0], 2.0, stream="audited").reason for t in range(10)}
    shield.step([0.5, 5.0, 1.0], None, stream="audited", done=True, event="collision")
    assert "audit" in reasons and not reasons & {"revised_safety", "revised_speed"}
    assert np.array_equal(risk_parts(shield).record.counts[: counts.shape[0]], counts)
    assert np.array_equal(risk_parts(shield).record.bands, bands)
    assert (risk_parts(shield).trial.counts - trial).tolist() == [[0, 0], [1, 1]]


def test_no_episode_is_drawn_before_a_failure_was_learned_and_an_episode_has_ended() -> None:
    shield = Shield(ShieldConfig())
    for t in range(5):  # a failure learned mid-stream, no episode ended: nothing drawn
        shield.step([float(t), 5.0, 1.0], 0.5, stream="s", event="collision" if t == 2 else None)
    assert shield.streams["s"].arm == NONE
    shield.step([1.0, 5.0, 1.0], 0.5, stream="other")  # a failure learned, no episode ended
    assert risk_parts(shield).local_risk.any_failure
    assert shield.streams["other"].arm == NONE
    shield.step([1.0, 5.0, 1.0], None, stream="s", done=True)
    assert not risk_parts(shield).trial.counts.any()  # its episode was outside the trial
    shield.step([1.0, 5.0, 1.0], 0.5, stream="s")  # the next episode's first step draws
    assert shield.streams["s"].arm in (SHIELDED, AUDITED)


def test_an_audit_ends_uncounted_past_twice_the_mean_episode_length() -> None:
    shield = harmful_shield()
    risk_parts(shield).trial.draw = lambda at: AUDITED  # type: ignore[method-assign]
    longest = 2.0 * shield.counters.steps / shield.counters.episodes
    trial = risk_parts(shield).trial.counts.copy()
    shield.step([0.5, 5.0, 1.0], 1.0, stream="long")
    audited = 0
    while shield.streams["long"].arm == AUDITED and audited <= longest + 1:
        shield.step([0.5, 5.0, 1.0], 1.0, stream="long")
        audited += 1
    assert shield.streams["long"].arm == NONE and audited >= int(longest) - 1
    shield.step([0.5, 5.0, 1.0], None, stream="long", done=True, event="collision")
    assert np.array_equal(
        risk_parts(shield).trial.counts, trial
    )  # the episode counted in neither arm
