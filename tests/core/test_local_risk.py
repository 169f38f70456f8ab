"""The risk reviser's local model: least squares on delayed labels, risk that
follows the observation within a state, snapshots, bad configurations."""

from __future__ import annotations

from typing import TypedDict

import numpy as np
import pytest

from app.core import InvalidSnapshot, Shield, ShieldConfig
from app.core.belief import Belief
from app.core.local_risk import PRIOR_COV, FloatArray, LocalRisk
from tests.core.checks import risk_parts
from tests.core.test_risk import crash_world
from tests.utils import assert_same


class Streams(TypedDict):
    """LocalRisk's stream sizes."""

    belief_size: int
    max_streams: int


LOCAL = {"risk": {"horizon": 4}}
SAFE = np.array([-1, 1], dtype=np.int64)  # collision-like, then falling-behind-like
ONE_STREAM: Streams = {"belief_size": 4, "max_streams": 1}  # every test stream in slot 0


def one_state(weight: float = 1.0) -> Belief:
    return Belief(np.array([0]), np.array([weight]))


def features(model: LocalRisk, z: FloatArray, action_bin: int) -> FloatArray:
    """``phi(z, u) = [1, z, u]``, u the bin's midpoint scaled to [0, 1]."""
    return np.array([1.0, *z, model.midpoints[action_bin]])


def test_the_fit_is_weighted_ridge_least_squares_on_the_labelled_steps() -> None:
    rng = np.random.default_rng(0)
    model = LocalRisk(dim=2, n_criteria=2, n_bins=5, horizon=1, max_states=4, **ONE_STREAM)
    model.add_state()
    rows, labels, weights = [], [], []
    for _ in range(200):
        z, action_bin, weight = rng.uniform(0, 1, 2), int(rng.integers(5)), rng.uniform(0.1, 1)
        failure = int(rng.integers(2)) if rng.random() < 0.2 else None
        # each step ends its own episode, so it is labelled at once
        model.learn(0, one_state(weight), z, action_bin, failure, ended=True)
        rows.append(features(model, z, action_bin))
        labels.append([failure == c for c in range(2)])
        weights.append(weight)
    x, y, w = np.array(rows), np.array(labels, dtype=float), np.array(weights)
    ridge = x.T @ (w[:, None] * x) + np.eye(4) / PRIOR_COV
    expected = np.linalg.solve(ridge, x.T @ (w[:, None] * y)).T
    assert np.allclose(model.theta[0], expected, atol=1e-9)


def test_a_step_is_labelled_safe_after_the_horizon_and_failed_when_a_failure_follows() -> None:
    model = LocalRisk(dim=1, n_criteria=2, n_bins=3, horizon=3, max_states=2, **ONE_STREAM)
    model.add_state()
    z = np.array([0.5])
    for _ in range(5):  # five safe steps: the first two are older than the horizon
        model.learn(0, one_state(), z, 1, None, ended=False)
    assert model.pending(0) == 3  # two were labelled safe
    safe = model.theta.copy()
    model.learn(0, one_state(), z, 2, 1, ended=True)  # a failure of criterion 1
    assert model.pending(0) == 0 and model.failures.tolist() == [0, 1]
    risk = np.empty((3, 2))
    model.read(one_state(), z, SAFE, risk)
    assert risk[1, 1] > 0.1 and risk[1, 0] == 0.0  # criterion 1's risk rose, 0's did not
    assert not np.array_equal(model.theta, safe)


def test_an_untried_bin_takes_its_nearest_tried_bin_on_the_safe_side_or_none() -> None:
    # one state, bins 0..4; only bins 1 and 3 applied there, both ended in failures of both
    model = LocalRisk(dim=1, n_criteria=2, n_bins=5, horizon=1, max_states=2, **ONE_STREAM)
    model.add_state()
    for t in range(30):
        model.learn(0, one_state(), np.array([0.5]), 1 + 2 * (t % 2), t % 2, ended=True)
    risk = np.empty((5, 2))
    model.read(one_state(), np.array([0.5]), SAFE, risk)
    tried = np.empty((5, 2))
    tried[:] = np.nan
    for b in (1, 3):
        value = model.theta[0] @ features(model, np.array([0.5]), b)
        tried[b] = np.clip(value, 0.0, 1.0)
    # criterion 0 is safe towards bin 0: bin 0 has nothing tried on its safe side
    assert risk[:, 0].tolist() == pytest.approx(
        [0.0, tried[1, 0], tried[1, 0], tried[3, 0], tried[3, 0]]
    )
    # criterion 1 is safe towards bin 4
    assert risk[:, 1].tolist() == pytest.approx(
        [tried[1, 1], tried[1, 1], tried[3, 1], tried[3, 1], 0.0]
    )
    assert model.tried[0].tolist() == [0, 15, 0, 15, 0]


def test_bins_safer_than_every_bin_applied_near_the_observation_carry_no_risk_there() -> None:
    # one broad state, a controller that brakes (bin 1) only when it is too late, at small x,
    # and cruises (bin 3) at large x: braking is learned with crashing (the confound)
    model = LocalRisk(dim=1, n_criteria=1, n_bins=5, horizon=1, max_states=2, **ONE_STREAM)
    model.add_state()
    rng = np.random.default_rng(2)
    for t in range(200):
        brake = t % 2 == 0
        x = rng.uniform(0.0, 0.3) if brake else rng.uniform(0.6, 1.0)
        model.learn(
            0, one_state(), np.array([x]), 1 if brake else 3, 0 if brake else None, ended=True
        )

    def model_at(x: float, b: int) -> float:
        return float(np.clip(model.theta[0, 0] @ features(model, np.array([x]), b), 0, 1))

    far, near = np.empty((5, 1)), np.empty((5, 1))
    model.read(one_state(), np.array([0.8]), SAFE[:1], far)
    model.read(one_state(), np.array([0.1]), SAFE[:1], near)
    assert model_at(0.8, 1) > 0.1  # what the state-wide model says of braking at x = 0.8
    # at x = 0.8 only bin 3 was applied: braking there is untried, so it carries no risk
    assert far[:, 0].tolist() == pytest.approx([0.0, 0.0, 0.0, model_at(0.8, 3), model_at(0.8, 3)])
    # at x = 0.1 braking was applied: its model answers, and the state's for bin 3
    assert near[:, 0].tolist() == pytest.approx(
        [0.0, model_at(0.1, 1), model_at(0.1, 1), model_at(0.1, 3), model_at(0.1, 3)]
    )
    assert near[1, 0] > 0.5


def test_a_snapshot_without_boxes_restores_with_none_and_a_bad_box_is_refused() -> None:
    shield = Shield(ShieldConfig.from_dict(LOCAL))
    crash_world(shield, 10, seed=6)
    data = shield.snapshot()
    local = data["local_risk"]
    assert_same(Shield.from_snapshot(data).snapshot()["local_risk"], local)
    older = {k: v for k, v in local.items() if k not in ("low", "high")}
    restored = risk_parts(Shield.from_snapshot({**data, "local_risk": older})).local_risk
    assert restored is not None
    boxes = restored.snapshot({})
    assert (boxes["low"] == 1.0).all() and (boxes["high"] == 0.0).all()  # all empty
    assert_same(restored.theta, risk_parts(shield).local_risk.theta)
    assert_same(
        Shield.from_snapshot(
            Shield.from_snapshot({**data, "local_risk": older}).snapshot()
        ).snapshot()["local_risk"],
        boxes,
    )
    half = local["low"].copy()
    applied = local["tried"] > 0
    half[applied, 0] = local["high"][applied, 0] + 1.0  # one dimension upside down
    with pytest.raises(InvalidSnapshot) as error:
        Shield.from_snapshot({**data, "local_risk": {**local, "low": half}})
    assert error.value.field == "local_risk.low"


def test_a_failure_stays_visible_after_many_safe_tries_of_another_action() -> None:
    model = LocalRisk(dim=1, n_criteria=1, n_bins=5, horizon=1, max_states=2, **ONE_STREAM)
    model.add_state()
    z = np.array([0.5])
    for t in range(5):  # bin 4: one failure in five tries
        model.learn(0, one_state(), z, 4, 0 if t == 0 else None, ended=True)
    for _ in range(10_000):  # bin 0: always safe
        model.learn(0, one_state(), z, 0, None, ended=True)
    risk = np.empty((5, 1))
    model.read(one_state(), z, SAFE[:1], risk)
    assert risk[4, 0] == pytest.approx(0.2, abs=0.01) and risk[0, 0] < 1e-3


def test_the_risk_follows_the_observation_within_one_state() -> None:
    # one broad state; failures follow only from small x: far from them the risk stays low
    model = LocalRisk(dim=1, n_criteria=1, n_bins=3, horizon=2, max_states=2, **ONE_STREAM)
    model.add_state()
    rng = np.random.default_rng(1)
    for _ in range(400):
        x = rng.uniform(0, 1)
        model.learn(0, one_state(), np.array([x]), 1, 0 if x < 0.2 else None, ended=True)
    near, far = np.empty((3, 1)), np.empty((3, 1))
    model.read(one_state(), np.array([0.05]), SAFE[:1], near)
    model.read(one_state(), np.array([0.9]), SAFE[:1], far)
    assert near[1, 0] > 0.2 and far[1, 0] < 0.05


def test_the_shield_learns_to_refuse_the_action_that_crashed() -> None:
    config = ShieldConfig.from_dict({**LOCAL, "reviser": {"activate_after_episodes": 20}})
    shield = Shield(config)
    crash_world(shield, 20, seed=1)
    assert risk_parts(shield).local_risk.failures.sum() > 0
    # (asked of a stream outside the trial, app.core.trial: an audited episode passes it)
    decision = shield.step([28.0, 20.0, 10.0], 1.9, stream="probe", learn=False)
    assert decision.revised and decision.action is not None and decision.action < 1.9
    assert decision.risk["collision"] > 0.0 and decision.candidates
    later = crash_world(shield, 50, seed=2)
    assert later < crash_world(
        Shield(ShieldConfig.from_dict({**LOCAL, "reviser": {"activate_after_episodes": 10**6}})),
        50,
        seed=2,
    )


def test_a_model_with_pending_steps_round_trips_and_decides_alike() -> None:
    config = ShieldConfig.from_dict(LOCAL)
    shield = Shield(config)
    crash_world(shield, 15, seed=3)
    for t in range(3):  # a stream left in the middle of an episode
        shield.step([12.0 + t, 30.0, 11.0], 0.5, stream="open")
    assert (
        risk_parts(shield).local_risk.pending(shield.streams["open"].slot) == 2
    )  # (the first: none)
    copy = Shield.from_snapshot(shield.snapshot())
    assert_same(copy.snapshot(), shield.snapshot())
    for speed in (25.0, 28.0, 12.0):
        first = shield.step([speed, 20.0, 10.0], 1.9, stream="open")
        second = copy.step([speed, 20.0, 10.0], 1.9, stream="open")
        assert first.to_dict() == second.to_dict()
    twin, again = Shield(config), Shield(config)
    crash_world(twin, 15, seed=3)  # deterministic: the same inputs make the same model
    crash_world(again, 15, seed=3)
    assert_same(again.snapshot()["local_risk"], twin.snapshot()["local_risk"])


def test_a_stream_that_ends_frees_its_slot_and_the_next_stream_starts_empty() -> None:
    shield = Shield(ShieldConfig.from_dict(LOCAL))
    crash_world(shield, 5, seed=7)
    for t in range(3):
        shield.step([12.0 + t, 30.0, 11.0], 0.5, stream="a")
        shield.step([20.0, 40.0 + t, 19.0], -0.5, stream="b")
    slot_a, slot_b = shield.streams["a"].slot, shield.streams["b"].slot
    assert slot_a != slot_b and risk_parts(shield).local_risk.pending(slot_a) == 2
    shield.step([15.0, 30.0, 11.0], None, stream="a", done=True)
    assert risk_parts(shield).local_risk.pending(slot_a) == 0  # labelled at the episode's end
    shield.step([12.0, 30.0, 11.0], 0.5, stream="c")
    shield.step([13.0, 30.0, 11.0], 0.5, stream="c")
    assert shield.streams["c"].slot == slot_a and risk_parts(shield).local_risk.pending(slot_a) == 1
    assert risk_parts(shield).local_risk.pending(slot_b) == 2  # b's steps are its own
    copy = Shield.from_snapshot(shield.snapshot())
    assert_same(copy.snapshot(), shield.snapshot())


@pytest.mark.parametrize(
    ("damage", "field"),
    [
        ("theta", "local_risk.theta"),
        ("tried", "local_risk.tried"),
        ("cov", "local_risk.cov"),
        ("lengths", "local_risk.lengths"),
        ("index", "local_risk.index"),
        ("stream", "local_risk.streams"),
        ("twice", "local_risk.streams"),
    ],
)
def test_a_damaged_local_model_is_refused_naming_its_part(damage: str, field: str) -> None:
    shield = Shield(ShieldConfig.from_dict(LOCAL))
    crash_world(shield, 10, seed=4)
    shield.step([12.0, 30.0, 11.0], 0.5, stream="open")
    shield.step([12.0, 31.0, 11.0], 0.5, stream="open")
    data = shield.snapshot()
    local = data["local_risk"]
    if damage == "theta":
        local["theta"] = local["theta"][:-1]
    elif damage == "tried":
        local["tried"] = -local["tried"] - 1
    elif damage == "cov":
        local["cov"] = local["cov"] * 1e6
    elif damage == "lengths":
        local["lengths"] = local["lengths"] + 10
    elif damage == "index":
        local["index"] = local["index"] + 10_000
    elif damage == "twice":  # one stream's steps listed twice: more than its ring holds
        for key in ("streams", "lengths", "sizes", "index", "prob", "phi"):
            value = local[key]
            local[key] = value * 2 if isinstance(value, list) else np.concatenate([value] * 2)
    else:
        local["streams"] = ["nobody"]
    with pytest.raises(InvalidSnapshot) as error:
        Shield.from_snapshot(data)
    assert error.value.field == field


def test_extreme_observations_leave_every_risk_a_probability() -> None:
    shield = Shield(ShieldConfig.from_dict(LOCAL))
    crash_world(shield, 10, seed=5)
    rng = np.random.default_rng(5)
    for t in range(300):
        big = [float(v) for v in rng.choice([-1e12, 1e12, 0.0, 1e-300], 3)]  # the bounds
        decision = shield.step(
            big,
            float(rng.uniform(-2, 2)),
            done=t % 20 == 19,
            event="collision" if t % 40 == 39 else None,
        )
        for value in decision.risk.values():
            assert 0.0 <= value <= 1.0
    assert np.isfinite(risk_parts(shield).local_risk.theta).all()
