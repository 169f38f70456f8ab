"""The risk reviser's decision: the monotone prior, the choice, the shield that learns to
refuse what crashed, bad configurations."""

from __future__ import annotations

import numpy as np
import pytest

from app.core import InvalidConfig, Shield, ShieldConfig
from app.core.risk import choose, decide, kept_limit, monotone, safe_steps
from tests.core import reference

RISK = {"method": "risk"}


def test_monotone_prior_runs_from_each_criterion_safe_end() -> None:
    by_bin = np.array([[0.0, 0.3], [0.2, 0.0], [0.1, 0.0], [0.0, 0.1]])  # 4 actions
    monotone(by_bin, safe_steps(["decrease", "increase"]))
    assert by_bin[:, 0].tolist() == [0.0, 0.2, 0.2, 0.2]  # slower is safer: max from the left
    assert by_bin[:, 1].tolist() == [0.3, 0.1, 0.1, 0.1]  # faster is safer: max from the right


@pytest.mark.parametrize("seed", range(10))
def test_the_compiled_monotone_prior_gives_the_numpy_reading(seed: int) -> None:
    rng = np.random.default_rng(seed)
    by_bin = rng.choice([0.0, 0.01, 0.2, 0.5], size=(9, 2))
    expected = reference.monotone(by_bin[None], ["decrease", "increase"])[0]
    monotone(by_bin, safe_steps(["decrease", "increase"]))
    np.testing.assert_array_equal(by_bin, expected)


def test_choose_keeps_a_safe_proposal_and_otherwise_the_nearest_allowed() -> None:
    def pick(total: list[float], proposed: int, safe_step: int) -> int:
        risks = np.array(total)
        return choose(risks, proposed, kept_limit(risks, 0.05, 0.02), safe_step)

    total = [0.0, 0.01, 0.03, 0.3, 0.6]
    assert pick(total, 2, -1) == 2  # under the threshold
    assert pick(total, 4, -1) == 2  # nearest under the threshold
    assert pick([0.5, 0.51, 0.9], 1, -1) == 1  # within the margin
    assert pick([0.0, 0.9, 0.0], 1, -1) == 0  # tie: the safe side
    assert pick([0.0, 0.9, 0.0], 1, 1) == 2


@pytest.mark.parametrize("seed", range(20))
def test_choose_gives_the_numpy_reading(seed: int) -> None:
    rng = np.random.default_rng(seed)
    total = rng.choice([0.0, 0.01, 0.2, 0.5], size=9)
    proposed, step = int(rng.integers(9)), int(rng.choice([-1, 1]))
    limit = kept_limit(total, 0.0, 0.001)
    assert choose(total, proposed, limit, step) == reference.choose(total, proposed, limit, step)


def test_decide_gives_verdicts_and_chooses_on_the_safe_side() -> None:
    by_bin = np.array([[0.0, 0.15], [0.0, 0.0], [0.6, 0.0]])  # braking falls behind, ...
    verdicts = np.empty(3, dtype=np.int64)
    limit, worst, final, kept = decide(by_bin, 2, 0.0, 0.001, safe_steps(
        ["decrease", "increase"]), verdicts)
    assert limit == pytest.approx(0.001) and worst == 0 and final == 1 and not kept
    assert verdicts.tolist() == [1, -1, 0]  # falling behind, within the limit, collision
    assert decide(by_bin, 1, 0.0, 0.001, safe_steps(["decrease", "increase"]),
                  verdicts)[2:] == (1, True)


def crash_world(shield: Shield, episodes: int, seed: int) -> int:
    """A point that crashes when it is fast near the wall: speeding up there always fails."""
    rng = np.random.default_rng(seed)
    crashes = 0
    for _ in range(episodes):
        for _ in range(30):
            speed = float(rng.uniform(0, 30))
            decision = shield.step([speed, 20.0, 10.0], float(rng.uniform(-2, 2)))
            assert decision.action is not None
            if speed > 20 and decision.action > 1.0:
                shield.step([speed, 0.0, 10.0], None, done=True, event="collision")
                crashes += 1
                break
        else:
            shield.step([10.0, 20.0, 10.0], None, done=True)
    return crashes


def test_the_shield_learns_to_refuse_the_action_that_crashed() -> None:
    config = ShieldConfig.from_dict({"reviser": {**RISK, "activate_after_episodes": 20}})
    shield = Shield(config)
    crash_world(shield, 20, seed=1)
    decision = shield.step([28.0, 20.0, 10.0], 1.9)
    assert decision.revised and decision.action is not None and decision.action <= 1.0
    assert decision.risk["collision"] > 0.05 and decision.candidates
    assert decision.candidates[-1].verdict == "ok" and decision.candidates[-1].risk is not None
    later = crash_world(shield, 50, seed=2)
    assert later < crash_world(Shield(ShieldConfig.from_dict(
        {"reviser": {**RISK, "activate_after_episodes": 10**6}})), 50, seed=2) / 2


@pytest.mark.parametrize(("event", "safe_end"), [("collision", -2.0),
                                                  ("large_distance", 2.0)])
def test_a_revision_applies_the_bins_midpoint_and_an_end_bin_the_range_end(
        event: str, safe_end: float) -> None:
    # a point that fails whenever it moves towards the criterion's side: revisions go to the
    # safe side, some of them to its end bin, which applies the end of the range (-2 or 2, the
    # hardest braking or pushing), not its midpoint (-1.9 or 1.9); the others their midpoints.
    # Without the reach: its paths all run through the failures seen at this one observation,
    # and where no bin avoids a failure the reach sends every revision to the end bin.
    shield = Shield(ShieldConfig.from_dict({"reviser": {**RISK, "activate_after_episodes": 20},
                                            "risk": {"reach_horizon": 0}}))
    rng = np.random.default_rng(3)
    revised = []
    for _ in range(60):
        for _ in range(20):
            decision = shield.step([25.0 + rng.normal(0, 0.1), 20.0, 10.0],
                                   float(rng.uniform(-2, 2)))
            assert decision.action is not None
            revised += [decision] if decision.revised else []
            if decision.action * safe_end < 0:
                shield.step([25.0, 20.0, 10.0], None, done=True, event=event)
                break
    applied = {d.candidates[-1].bin: d.action for d in revised}
    assert applied[0 if safe_end < 0 else 19] == safe_end  # the end bin: the range's end
    middle = [b for b in applied if 0 < b < 19]
    assert middle and all(applied[b] == pytest.approx(-1.9 + 0.2 * b) for b in middle)
    assert all(d.candidates[-1].action == d.action for d in revised)


def test_the_risk_reviser_is_deterministic_and_round_trips_its_snapshot() -> None:
    config = ShieldConfig.from_dict({"reviser": {**RISK, "activate_after_episodes": 5}})
    a, b = Shield(config), Shield(config)
    crash_world(a, 30, seed=3)
    crash_world(b, 30, seed=3)
    assert a.step([25.0, 20.0, 10.0], 1.5, stream="x") == b.step([25.0, 20.0, 10.0], 1.5,
                                                                   stream="x")
    restored = Shield.from_snapshot(a.snapshot())
    for speed in (5.0, 22.0, 29.0):
        assert restored.step([speed, 20.0, 10.0], 1.5, stream="x") == a.step(
            [speed, 20.0, 10.0], 1.5, stream="x")
    assert restored.local_risk is not None and a.local_risk is not None
    assert np.array_equal(restored.local_risk.theta, a.local_risk.theta)


@pytest.mark.parametrize(("overrides", "field"), [
    ({"risk": {"horizon": 0}}, "risk.horizon"),
    ({"risk": {"threshold": 1.5}}, "risk.threshold"),
    ({"risk": {"model": "counts"}}, "risk.model"),  # removed: an unknown field now
    ({"reviser": {"method": "oracle"}}, "reviser.method"),
    ({"observation": {"features": [{"name": "x", "weights": [1], "low": 0, "high": 1}]}},
     "observation.features.0.weights"),
    ({"observation": {"cluster_raw": False}}, "observation.cluster_raw"),
    ({"observation": {"features": [{"name": "headway", "weights": [0, 1, 0], "low": 0,
                                    "high": 1}]}}, "observation.features"),
])
def test_bad_risk_configurations_name_their_field(overrides: dict[str, object],
                                                  field: str) -> None:
    with pytest.raises(InvalidConfig) as error:
        ShieldConfig.from_dict(overrides)
    assert error.value.field == field


def test_features_are_clustered_beside_or_instead_of_the_observation() -> None:
    closing = {"name": "closing", "weights": [1, 0, -1], "low": -10, "high": 10}
    ratio = {"name": "time_headway", "weights": [0, 1, 0], "divide_by": [1, 0, 0],
             "floor": 1.0, "low": 0, "high": 4}
    beside = Shield(ShieldConfig.from_dict({"observation": {"features": [closing, ratio]}}))
    z = beside.normalise(np.array([20.0, 30.0, 15.0]))
    assert z.shape == (5,)
    assert z[3] == pytest.approx((5 + 10) / 20) and z[4] == pytest.approx(1.5 / 4)
    assert beside.normalise(np.array([0.0, 30.0, 0.0]))[4] == 1.0  # 30 / max(0, 1), clipped
    unbounded = [{"name": "collision", "direction": "decrease"},  # no headway to bound
                 {"name": "large_distance", "direction": "increase"}]
    alone = Shield(ShieldConfig.from_dict(
        {"observation": {"features": [closing], "cluster_raw": False}, "criteria": unbounded}))
    assert alone.normalise(np.array([20.0, 30.0, 15.0])).tolist() == [0.75]
    assert alone.physical(np.array([0.75])).tolist() == [5.0]


def test_the_paper_reviser_keeps_no_risk_model() -> None:
    shield = Shield(ShieldConfig.paper())
    crash_world(shield, 5, seed=5)
    assert shield.local_risk is None and shield.snapshot()["local_risk"] is None
