"""The risk reviser's decision: the monotone prior, the choice, the shield that learns to
refuse what crashed, bad configurations."""

from __future__ import annotations

import numpy as np
import pytest

from app.core import InvalidConfig, Shield, ShieldConfig
from app.core.revisers import RiskReviser
from app.core.risk import decide, monotone, safe_steps
from tests.core import reference
from tests.core.checks import risk_parts

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


def test_a_criterion_without_a_direction_keeps_its_risks_as_learned() -> None:
    by_bin = np.array([[0.3], [0.0], [0.2]])
    monotone(by_bin, safe_steps([None]))
    assert by_bin[:, 0].tolist() == [0.3, 0.0, 0.2]


def verdicts_of(
    by_bin: np.ndarray,
    reached: np.ndarray | None,
    proposed: int,
    threshold: float = 0.0,
    margin: float = 0.001,
) -> tuple[float, int, int, bool]:
    verdicts = np.empty(by_bin.shape[0], dtype=np.int64)
    return decide(
        by_bin.copy(),
        np.zeros_like(by_bin) if reached is None else reached,
        reached is not None,
        proposed,
        threshold,
        margin,
        verdicts,
    )


def test_the_decision_reads_the_total_risk_of_every_criterion_together() -> None:
    # bin 0 risks one failure, bin 2 another, bin 1 a little of both: bin 1 is the safest in
    # total (1 - 0.9 * 0.9 = 0.19 against 0.3), whatever criterion the proposal risks most
    by_bin = np.array([[0.3, 0.0], [0.1, 0.1], [0.0, 0.3]])
    limit, worst, final, kept = verdicts_of(by_bin, None, 2)
    assert (worst, final, kept) == (1, 1, False) and limit == pytest.approx(0.19 + 0.001)
    assert verdicts_of(by_bin, None, 1)[2:] == (1, True)


def test_a_proposal_within_the_margin_of_the_least_risk_is_kept() -> None:
    by_bin = np.array([[0.50], [0.52], [0.7]])
    assert verdicts_of(by_bin, None, 1, margin=0.05)[2:] == (1, True)
    assert verdicts_of(by_bin, None, 2, margin=0.05)[2:] == (1, False)  # the nearest allowed
    assert verdicts_of(by_bin, None, 2, threshold=0.8)[2:] == (2, True)  # under the threshold


def test_where_no_action_is_safe_the_least_risky_nearest_applies_never_an_extreme_by_rule() -> None:
    # every action risks a failure; the least (bin 2) is in the middle, not at an end
    by_bin = np.array([[0.9, 0.0], [0.0, 0.7], [0.4, 0.0], [0.8, 0.0], [0.95, 0.0]])
    assert verdicts_of(by_bin, None, 4)[2:] == (2, False)
    assert verdicts_of(by_bin, None, 0)[2:] == (2, False)


def test_of_two_allowed_bins_equally_near_the_less_risky_applies() -> None:
    by_bin = np.array([[0.02], [0.9], [0.0]])
    assert verdicts_of(by_bin, None, 1, margin=0.05)[2] == 2
    by_bin = np.array([[0.0], [0.9], [0.02]])
    assert verdicts_of(by_bin, None, 1, margin=0.05)[2] == 0


def test_the_reach_blends_with_the_local_risk_neither_outranking_the_other() -> None:
    # the local model reads every action alike (a confound); the reach tells them apart
    by_bin = np.full((5, 1), 0.3)
    reached = np.zeros((5, 1))
    reached[2:, 0] = 1.0
    verdicts = np.empty(5, dtype=np.int64)
    blended = by_bin.copy()
    limit, worst, final, kept = decide(blended, reached, True, 4, 0.0, 0.001, verdicts)
    assert (worst, final, kept) == (0, 1, False) and verdicts.tolist() == [-1, -1, 0, 0, 0]
    assert blended[:, 0].tolist() == [0.15, 0.15, 0.65, 0.65, 0.65]  # what the record shows
    # and where the local model has learned a failure the reach misses, it still counts
    local = np.array([[0.0], [0.0], [0.8]])
    assert verdicts_of(local, np.zeros((3, 1)), 2)[2:] == (1, False)


@pytest.mark.parametrize("seed", range(30))
def test_the_compiled_decision_gives_the_numpy_reading(seed: int) -> None:
    rng = np.random.default_rng(seed)
    by_bin = rng.choice([0.0, 0.01, 0.2, 0.5, 1.0], size=(9, 2))
    reached = rng.choice([0.0, 0.3, 0.9], size=(9, 2)) if seed % 2 else None
    proposed, margin = int(rng.integers(9)), float(rng.choice([0.001, 0.05]))
    limit, worst, final, _ = verdicts_of(by_bin, reached, proposed, margin=margin)
    expected = reference.decide(by_bin, reached, proposed, 0.0, margin)
    assert (worst, final) == expected[1:] and limit == pytest.approx(expected[0], abs=1e-15)


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
    # (asked of a stream outside the trial, app.core.trial: an audited episode passes it)
    decision = shield.step([28.0, 20.0, 10.0], 1.9, stream="probe", learn=False)
    assert decision.revised and decision.action is not None and decision.action <= 1.0
    assert decision.risk["collision"] > 0.05 and decision.candidates
    assert decision.candidates[-1].verdict == "ok" and decision.candidates[-1].risk is not None
    later = crash_world(shield, 50, seed=2)
    assert (
        later
        < crash_world(
            Shield(ShieldConfig.from_dict({"reviser": {**RISK, "activate_after_episodes": 10**6}})),
            50,
            seed=2,
        )
        / 2
    )


@pytest.mark.parametrize(("event", "safe_end"), [("collision", -2.0), ("large_distance", 2.0)])
def test_a_revision_applies_the_bins_midpoint_and_an_end_bin_the_range_end(
    event: str, safe_end: float
) -> None:
    # a point that fails whenever it moves towards the criterion's side: revisions go to the
    # safe side, some of them to its end bin, which applies the end of the range (-2 or 2, the
    # hardest braking or pushing), not its midpoint (-1.9 or 1.9); the others their midpoints.
    # Without the reach: its paths all run through the failures seen at this one observation,
    # and where no bin avoids a failure the reach sends every revision to the end bin.
    shield = Shield(
        ShieldConfig.from_dict(
            {"reviser": {**RISK, "activate_after_episodes": 20}, "risk": {"reach_horizon": 0}}
        )
    )
    rng = np.random.default_rng(3)
    revised = []
    for _ in range(60):
        for _ in range(20):
            decision = shield.step(
                [25.0 + rng.normal(0, 0.1), 20.0, 10.0], float(rng.uniform(-2, 2))
            )
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
    assert a.step([25.0, 20.0, 10.0], 1.5, stream="x") == b.step(
        [25.0, 20.0, 10.0], 1.5, stream="x"
    )
    restored = Shield.from_snapshot(a.snapshot())
    for speed in (5.0, 22.0, 29.0):
        assert restored.step([speed, 20.0, 10.0], 1.5, stream="x") == a.step(
            [speed, 20.0, 10.0], 1.5, stream="x"
        )
    assert np.array_equal(risk_parts(restored).local_risk.theta, risk_parts(a).local_risk.theta)


@pytest.mark.parametrize(
    ("overrides", "field"),
    [
        ({"risk": {"horizon": 0}}, "risk.horizon"),
        ({"risk": {"threshold": 1.5}}, "risk.threshold"),
        ({"risk": {"model": "counts"}}, "risk.model"),  # removed: an unknown field now
        ({"reviser": {"method": "oracle"}}, "reviser.method"),
        (
            {"observation": {"features": [{"name": "x", "weights": [1], "low": 0, "high": 1}]}},
            "observation.features.0.weights",
        ),
        ({"observation": {"cluster_raw": False}}, "observation.cluster_raw"),
        (
            {
                "observation": {
                    "features": [{"name": "headway", "weights": [0, 1, 0], "low": 0, "high": 1}]
                }
            },
            "observation.features",
        ),
    ],
)
def test_bad_risk_configurations_name_their_field(overrides: dict[str, object], field: str) -> None:
    with pytest.raises(InvalidConfig) as error:
        ShieldConfig.from_dict(overrides)
    assert error.value.field == field


def test_features_are_clustered_beside_or_instead_of_the_observation() -> None:
    closing = {"name": "closing", "weights": [1, 0, -1], "low": -10, "high": 10}
    ratio = {
        "name": "time_headway",
        "weights": [0, 1, 0],
        "divide_by": [1, 0, 0],
        "floor": 1.0,
        "low": 0,
        "high": 4,
    }
    beside = Shield(ShieldConfig.from_dict({"observation": {"features": [closing, ratio]}}))
    z = beside.normalise(np.array([20.0, 30.0, 15.0]))
    assert z.shape == (5,)
    assert z[3] == pytest.approx((5 + 10) / 20) and z[4] == pytest.approx(1.5 / 4)
    assert beside.normalise(np.array([0.0, 30.0, 0.0]))[4] == 1.0  # 30 / max(0, 1), clipped
    unbounded = [
        {"name": "collision", "direction": "decrease"},  # no headway to bound
        {"name": "large_distance", "direction": "increase"},
    ]
    alone = Shield(
        ShieldConfig.from_dict(
            {"observation": {"features": [closing], "cluster_raw": False}, "criteria": unbounded}
        )
    )
    assert alone.normalise(np.array([20.0, 30.0, 15.0])).tolist() == [0.75]
    assert alone.physical(np.array([0.75])).tolist() == [5.0]


def test_the_paper_reviser_keeps_no_risk_model() -> None:
    shield = Shield(ShieldConfig.paper())
    crash_world(shield, 5, seed=5)
    assert not isinstance(shield.reviser, RiskReviser) and shield.snapshot()["local_risk"] is None


def test_a_criterion_declared_without_a_direction_learns_which_actions_fail() -> None:
    config = ShieldConfig.from_dict(
        {
            "criteria": [{"name": "collision", "direction": None}],
            "reviser": {**RISK, "activate_after_episodes": 20},
        }
    )
    assert config.criteria[0].direction is None
    shield = Shield(config)
    crash_world(shield, 20, seed=1)
    # (asked of a stream outside the trial, app.core.trial: an audited episode passes it)
    decision = shield.step([28.0, 20.0, 10.0], 1.9, stream="probe", learn=False)
    assert decision.revised and decision.action is not None and decision.action <= 1.0
    assert Shield.from_snapshot(shield.snapshot()).config == config


def test_the_papers_reviser_refuses_a_criterion_without_a_direction() -> None:
    with pytest.raises(InvalidConfig) as error:
        ShieldConfig.from_dict(
            {"criteria": [{"name": "fall", "direction": None}], "reviser": {"method": "paper"}}
        )
    assert error.value.field == "criteria.0.direction"
