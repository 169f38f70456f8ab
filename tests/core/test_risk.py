"""The failure-aware risk reviser: counts, horizon risk, the monotone prior, the decision."""

from __future__ import annotations

import numpy as np
import pytest

from app.core import InvalidConfig, InvalidSnapshot, Shield, ShieldConfig
from app.core.risk import (
    OutcomeCounts,
    choose,
    decide,
    horizon_risk,
    kept_limit,
    monotone,
    safe_steps,
)
from tests.core import reference

COLLISION = ["decrease"]


RISK = {"method": "risk"}


def counts(n: int, q: int, c: int) -> OutcomeCounts:
    out = OutcomeCounts(q, c, max_states=100)
    for _ in range(n):
        out.add_state()
    return out


def test_one_step_risk_is_the_posterior_mean_of_the_action_tried() -> None:
    model = counts(2, 2, 1)
    for _ in range(3):
        model.learn_move(0, 0, 1)  # action 0: three safe moves
    model.learn_failure(0, 1, 0)  # action 1: one try, one failure
    table = horizon_risk(model.tries, model.failures, model.moves(), COLLISION, 1, 1.0)
    assert table[0, :, 0].tolist() == [0.0, pytest.approx(1 / 2)]  # 1 / (1 + prior 1)
    assert table[1].sum() == 0.0  # nothing known of state 1


def test_two_step_risk_by_hand() -> None:
    # state 0 --a0--> state 1 (twice); state 1: a0 fails once in 4 tries, a1 safe 3 times
    model = counts(2, 2, 1)
    model.learn_move(0, 0, 1)
    model.learn_move(0, 0, 1)
    model.learn_failure(1, 0, 0)
    for _ in range(3):
        model.learn_move(1, 0, 1)
    for _ in range(3):
        model.learn_move(1, 1, 1)
    table = horizon_risk(model.tries, model.failures, model.moves(), COLLISION, 2, 1.0)
    # one step from 1: a0 = 1/5; a1 = 0, lifted to 1/5 by the monotone prior (a1 is faster)
    # -> V_1(1) = 0.2 (every tried action of state 1 is at 0.2)
    # two steps: Q(1, a0) = 1/5 + (3/5) * 0.2 = 0.32; Q(0, a0) = 0 + (2/3) * 0.2
    assert table[1, 0, 0] == pytest.approx(0.2 + 0.6 * 0.2)
    assert table[0, 0, 0] == pytest.approx(2 / 3 * 0.2)
    # a1 in state 0 was never tried: the risk of a0, its nearest tried action on the safe side
    assert table[0, 1, 0] == pytest.approx(table[0, 0, 0])


def test_the_safest_continuation_is_taken_after_the_first_step() -> None:
    # state 1: braking (a0) always safe, accelerating (a1) always fails
    model = counts(2, 2, 1)
    for _ in range(4):
        model.learn_move(0, 1, 1)
        model.learn_move(1, 0, 1)
        model.learn_failure(1, 1, 0)
    table = horizon_risk(model.tries, model.failures, model.moves(), COLLISION, 3, 1.0)
    assert table[1, 0, 0] == 0.0  # keep braking: never fails
    assert table[1, 1, 0] == pytest.approx(4 / 5)
    assert table[0, 1, 0] == 0.0  # into state 1, then brake


def test_monotone_prior_runs_from_each_criterion_safe_end() -> None:
    raw = np.array([[[0.0, 0.3], [0.2, 0.0], [0.1, 0.0], [0.0, 0.1]]])  # 1 state, 4 actions
    out = np.empty_like(raw)
    monotone(raw, safe_steps(["decrease", "increase"]), out)
    assert out[0, :, 0].tolist() == [0.0, 0.2, 0.2, 0.2]  # slower is safer: max from the left
    assert out[0, :, 1].tolist() == [0.3, 0.1, 0.1, 0.1]  # faster is safer: max from the right


def test_a_failure_stays_visible_after_many_safe_tries_of_other_actions() -> None:
    model = counts(1, 3, 1)
    model.learn_failure(0, 2, 0)  # accelerating crashed once
    for _ in range(10_000):
        model.learn_move(0, 0, 0)  # braking, safe, ten thousand times
    table = horizon_risk(model.tries, model.failures, model.moves(), COLLISION, 1, 1.0)
    assert table[0, 2, 0] == pytest.approx(0.5)
    assert table[0, 0, 0] == 0.0


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


def random_model(seed: int, n: int, q: int = 6, n_c: int = 2) -> OutcomeCounts:
    """Counts of random tries, moves and failures."""
    rng = np.random.default_rng(seed)
    model = counts(n, q, n_c)
    for _ in range(40 * n):
        state, action = int(rng.integers(n)), int(rng.integers(q))
        if rng.random() < 0.1:
            model.learn_failure(state, action, int(rng.integers(n_c)))
        else:
            model.learn_move(state, action, int(rng.integers(n)))
    return model


@pytest.mark.parametrize("seed", range(6))
def test_the_compiled_value_iteration_gives_the_numpy_reading_bit_for_bit(seed: int) -> None:
    model = random_model(seed, n=[1, 3, 40][seed % 3])
    directions = ["decrease", "increase"]
    for horizon in (1, 2, 8):
        args = (model.tries, model.failures, model.moves(), directions, horizon, 1.0)
        np.testing.assert_array_equal(horizon_risk(*args), reference.horizon_risk(*args))


@pytest.mark.parametrize("seed", range(20))
def test_choose_gives_the_numpy_reading(seed: int) -> None:
    rng = np.random.default_rng(seed)
    total = rng.choice([0.0, 0.01, 0.2, 0.5], size=9)
    proposed, step = int(rng.integers(9)), int(rng.choice([-1, 1]))
    limit = kept_limit(total, 0.0, 0.001)
    assert choose(total, proposed, limit, step) == reference.choose(total, proposed, limit, step)


def test_decide_reads_the_belief_risk_and_chooses_on_the_safe_side() -> None:
    table = np.zeros((2, 3, 2))
    table[0, 2, 0] = 0.8  # state 0: accelerating crashes
    table[1, 0, 1] = 0.6  # state 1: braking falls behind
    by_bin = np.empty((3, 2))
    index, prob = np.array([0, 1]), np.array([0.75, 0.25])
    verdicts = np.empty(3, dtype=np.int64)
    limit, worst, final, kept = decide(table, index, prob, 2, 0.0, 0.001, safe_steps(
        ["decrease", "increase"]), by_bin, verdicts)
    np.testing.assert_allclose(by_bin, [[0.0, 0.15], [0.0, 0.0], [0.6, 0.0]], atol=1e-15)
    assert limit == pytest.approx(0.001) and worst == 0 and final == 1 and not kept
    assert verdicts.tolist() == [1, -1, 0]  # falling behind, within the limit, collision


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
    assert np.array_equal(restored.outcomes.tries, a.outcomes.tries)


def test_a_snapshot_with_inconsistent_outcomes_is_refused() -> None:
    shield = Shield(ShieldConfig.from_dict({"reviser": RISK}))
    crash_world(shield, 5, seed=4)
    data = shield.snapshot()
    data["outcomes"]["tries"] = data["outcomes"]["tries"] + 1
    with pytest.raises(InvalidSnapshot):
        Shield.from_snapshot(data)
    data = shield.snapshot()
    data["risk"]["table"] = data["risk"]["table"] + np.nan
    with pytest.raises(InvalidSnapshot):
        Shield.from_snapshot(data)


@pytest.mark.parametrize(("overrides", "field"), [
    ({"risk": {"horizon": 0}}, "risk.horizon"),
    ({"risk": {"threshold": 1.5}}, "risk.threshold"),
    ({"risk": {"prior_safe": 0}}, "risk.prior_safe"),
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
    alone = Shield(ShieldConfig.from_dict(
        {"observation": {"features": [closing], "cluster_raw": False}}))
    assert alone.normalise(np.array([20.0, 30.0, 15.0])).tolist() == [0.75]
    assert alone.physical(np.array([0.75])).tolist() == [5.0]


def test_the_paper_reviser_counts_no_outcomes() -> None:
    shield = Shield(ShieldConfig.paper())
    crash_world(shield, 5, seed=5)
    assert shield.outcomes.tries.sum() == 0 and not shield.outcomes.any_failure
