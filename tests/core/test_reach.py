"""The reach (app.core.reach): learned dynamics, failure points, paths under the safest
continuation, and the decision that asks it before the local model."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from app.core import InvalidConfig, InvalidSnapshot, Shield, ShieldConfig, reach
from app.core.local_risk import PRIOR_COV
from tests.core import reference
from tests.core.checks import risk_parts
from tests.core.test_risk import crash_world
from tests.utils import assert_same

NO_COV = np.zeros((0, 0, 0))  # the dynamics' covariances, which the reach's risk does not read

SAFE = np.array([-1, 1], dtype=np.int64)  # collision-like, then falling-behind-like


def test_the_dynamics_are_weighted_ridge_least_squares_on_the_changes() -> None:
    rng = np.random.default_rng(0)
    dynamics, cov = np.zeros((2, 2, 4)), np.stack([np.eye(4) * PRIOR_COV] * 2)
    peak = np.zeros(2)
    truth = rng.normal(0, 0.3, (2, 4))
    rows, changes, weights = [], [], []
    for _ in range(100):
        before, u, weight = rng.uniform(0, 1, 2), rng.uniform(0, 1), rng.uniform(0.1, 1)
        phi = np.array([1.0, *before, u])
        after = before + truth @ phi + rng.normal(0, 0.01, 2)
        # the second state's weight is below the floor: it learns nothing
        reach.learn(dynamics, cov, peak, np.array([0, 1]), np.array([weight, 1e-4]), phi, after)
        rows.append(phi)
        changes.append(after - before)
        weights.append(weight)
    x, y, w = np.array(rows), np.array(changes), np.array(weights)
    ridge = x.T @ (w[:, None] * x) + np.eye(4) / PRIOR_COV
    expected = np.linalg.solve(ridge, x.T @ (w[:, None] * y)).T
    assert np.allclose(dynamics[0], expected, atol=1e-9)
    assert np.allclose(dynamics[0], truth, atol=0.02)
    assert not dynamics[1].any() and np.array_equal(cov[1], np.eye(4) * PRIOR_COV)


def test_the_peak_is_the_largest_error_of_learned_dynamics_and_fades() -> None:
    rng = np.random.default_rng(1)
    dynamics, cov = np.zeros((1, 1, 3)), np.eye(3)[None] * PRIOR_COV
    peak = np.zeros(1)

    def learn(noise: float) -> None:
        before, u = rng.uniform(0, 1, 1), rng.uniform(0, 1)
        after = before + 0.1 - 0.2 * u + noise
        reach.learn(
            dynamics, cov, peak, np.array([0]), np.array([1.0]), np.array([1.0, *before, u]), after
        )

    learn(5.0)  # a first error, before the dynamics are learned: it does not count
    assert peak[0] == 0.0 and cov[0, 0, 0] >= reach.SETTLED
    for _ in range(3000):
        learn(rng.uniform(-0.05, 0.05))
    assert cov[0, 0, 0] < reach.SETTLED
    assert 0.045 < peak[0] < 0.06  # the noise's largest, and the fit's small error
    learn(0.5)
    assert peak[0] == pytest.approx(0.5, abs=0.02)
    for _ in range(1000):
        learn(0.0)
    assert peak[0] == pytest.approx(0.5 * (1 - reach.PEAK_DECAY) ** 1000, rel=0.05)


def test_a_path_towards_a_failure_is_risky_and_one_away_from_it_is_not() -> None:
    # one dimension: z' - z = -0.2 + 0.4 u, so the slow bin (u 0.25) moves down by 0.1 a
    # step and the fast one (u 0.75) up by 0.1; a failure seen at 0.15
    dynamics, peak, extent = np.array([[[-0.2, 0.0, 0.4]]]), np.zeros(1), np.array([[0.0], [1.0]])
    points = np.zeros((1, reach.MAX_POINTS, 1))
    points[0, 0, 0] = 0.15
    counts = np.array([[1, 1]])
    out = np.empty((2, 1))
    for safe, expected in (
        (np.array([-1]), [0.5, 0.0]),  # safe: slow (down from 0.6)
        (np.array([1]), [0.0, 0.0]),
    ):  # safe: fast, back up after one
        reach.risk(
            (3, 0.1, dynamics, NO_COV, peak, points, counts, reach.no_bounds(1)),
            extent,
            np.array([0.25, 0.75]),
            np.array([0]),
            np.array([1.0]),
            np.array([0.5]),
            safe,
            out,
        )
        # slow first, then 3 steps: 0.4, 0.3, 0.2 (0.05 from the failure: half the radius)
        assert out[:, 0] == pytest.approx(expected)
    reach.risk(
        (3, 0.1, dynamics, NO_COV, peak, points, np.array([[0, 0]]), reach.no_bounds(1)),
        extent,
        np.array([0.25, 0.75]),
        np.array([0]),
        np.array([1.0]),
        np.array([0.5]),
        np.array([-1]),
        out,
    )
    assert not out.any()  # no failure seen and no bound: no risk


# Two dimensions: a gap h (bounded: failures at or below 0) and the speed v at which it
# closes, h' = h - v and v' = v - 0.1 + 0.2 u: the slow bin (u 0.25, the safe one) takes 0.05
# off the speed a step, the fast one (u 0.75) adds 0.05. From h 0.3, v 0.1, horizon 5.
CLOSING = np.array([[[0.0, 0.0, -1.0, 0.0], [-0.1, 0.0, 0.0, 0.2]]])


@pytest.mark.parametrize(
    ("peak", "expected"),
    [
        # no disturbance: slow, h 0.2, 0.15, 0.15 (v stays at the 0 seen, not below): never
        # (tau 6); fast: h 0.2, 0.05, then -0.05 halfway through the third step, tau 2.5
        (0.0, [0.0, (6 - 2.5) / 6]),
        # the speed may rise by 0.05 more a step: slow, v within [0, 0.1], so the gap's low end
        # goes 0.2, 0.1, 0.0: tau 3; fast, v within [0.1, 0.2]: 0.2, then 0.0, tau 2. Both
        # cross: only the fast bin's earlier crossing counts, by the step it comes sooner
        (0.05, [0.0, (3 - 2) / 6]),
    ],
)
def test_a_bound_fails_an_action_when_the_box_of_its_worst_cases_reaches_it(
    peak: float, expected: list[float]
) -> None:
    bounds = reach.no_bounds(1)
    bounds[0, 0], bounds[0, 1] = 0, 0.0
    out = np.empty((2, 1))
    reach.risk(
        (
            5,
            0.1,
            CLOSING,
            NO_COV,
            np.array([0.0, peak]),
            np.zeros((1, reach.MAX_POINTS, 2)),
            np.array([[0, 0]]),
            bounds,
        ),
        np.array([[0.0, 0.0], [1.0, 1.0]]),
        np.array([0.25, 0.75]),
        np.array([0]),
        np.array([1.0]),
        np.array([0.3, 0.1]),
        np.array([-1]),
        out,
    )
    assert out[:, 0] == pytest.approx(expected)


def test_the_box_stays_where_the_observation_was_seen() -> None:
    # h' = h + v, v' = v - 0.1 + 0.2 u, from h 0.3, v 0, the slow bin first and after, a
    # peak of 0.05 on v: kept at or above the 0 seen, v stays 0 and h 0.3; where nothing was
    # seen (an empty extent) v's low end goes -0.1, -0.2 and h's 0.3, 0.2, 0.0: tau 3
    opening = CLOSING.copy()
    opening[0, 0, 2] = 1.0
    bounds = reach.no_bounds(1)
    bounds[0, 0], bounds[0, 1] = 0, 0.0
    model, peak, z = opening[0], np.array([0.0, 0.05]), np.array([0.3, 0.0])
    seen, unseen = np.array([[0.0, 0.0], [1.0, 1.0]]), np.array([[np.inf] * 2, [-np.inf] * 2])

    def when(extent: np.ndarray, start: np.ndarray) -> float:
        out = np.empty(1)
        reach.crossings(model, peak, extent, start, np.array([0.25]), 0.25, 0, 0.0, np.inf, 5, out)
        return float(out[0])

    assert when(seen, z) == 6.0
    assert when(unseen, z) == 3.0
    assert when(seen, np.array([0.0, 0.0])) == 0.0  # at the bound already


@pytest.mark.parametrize("seed", range(5))
def test_the_reach_kernel_gives_the_reference_rollouts(seed: int) -> None:
    rng = np.random.default_rng(seed)
    d, q, n, horizon, radius = 3, 7, 4, 12, 0.3
    dynamics = rng.normal(0, 0.1, (n, d, d + 2))
    peak = rng.uniform(0, 0.05, d)
    extent = np.sort(rng.uniform(-0.5, 1.5, (2, d)), axis=0)
    extent[:, int(rng.integers(d))] = np.inf, -np.inf  # nothing seen on one dimension
    index, prob = np.array([0, 2, 3]), rng.dirichlet(np.ones(3))
    z, midpoints = rng.uniform(0, 1, d), (np.arange(q) + 0.5) / q
    points = np.zeros((2, reach.MAX_POINTS, d))
    points[:, :5] = rng.uniform(0, 1, (2, 5, d))
    # the first criterion fails at or below 0.1 of a random dimension, the second has no bound
    bounds, b = reach.no_bounds(2), int(rng.integers(d))
    bounds[0, 0], bounds[0, 1] = b, 0.1
    out = np.empty((q, 2))
    reach.risk(
        (horizon, radius, dynamics, NO_COV, peak, points, np.array([[5, 5], [5, 5]]), bounds),
        extent,
        midpoints,
        index,
        prob,
        z,
        SAFE,
        out,
    )
    for c, safe_bin in enumerate((0, q - 1)):
        expected = reference.reach(
            dynamics[index],
            prob,
            z,
            midpoints,
            safe_bin,
            points[c, :5],
            horizon,
            radius,
            peak,
            extent,
            (b, 0.1, np.inf) if c == 0 else None,
        )
        assert out[:, c] == pytest.approx(expected, abs=1e-12)


def test_failure_points_near_a_kept_one_add_nothing_and_the_oldest_goes_when_full() -> None:
    points = np.zeros((1, reach.MAX_POINTS, 1))
    counts = np.zeros((1, 2), dtype=np.int64)
    reach.add_failure(points, counts, 0, np.array([0.0]), 0.1)
    reach.add_failure(points, counts, 0, np.array([0.04]), 0.1)  # within half the radius
    assert counts.tolist() == [[1, 1]]
    for k in range(1, reach.MAX_POINTS + 1):
        reach.add_failure(points, counts, 0, np.array([float(k)]), 0.1)
    assert counts.tolist() == [[reach.MAX_POINTS, 1]]
    assert points[0, 0, 0] == reach.MAX_POINTS  # the first point was the oldest


def test_a_shield_learns_dynamics_and_failure_points_and_snapshots_them() -> None:
    shield = Shield(ShieldConfig())
    crash_world(shield, 20, seed=1)
    snapshot = shield.snapshot()["local_risk"]
    assert snapshot["point_counts"][0, 0] >= 1  # the collisions were kept
    assert np.abs(snapshot["dynamics"]).sum() > 0
    restored = Shield.from_snapshot(shield.snapshot())
    assert_same(restored.snapshot(), shield.snapshot())
    for t in range(50):
        observation, action = [10.0 + t % 7, 20.0 - t % 5, 12.0], float(t % 5) - 2
        assert (
            restored.step(observation, action).to_dict()
            == shield.step(observation, action).to_dict()
        )


def test_bounds_lie_in_the_clustering_space() -> None:
    shield = Shield(ShieldConfig())  # the collision's bound: a headway of 0
    assert risk_parts(shield).local_risk.bounds.tolist() == [
        [1.0, 0.0, np.inf],
        [-1.0, -np.inf, np.inf],
    ]
    both = [
        {
            "name": "near",
            "direction": "decrease",
            "bound": {"observation": "headway", "below": 5.0, "above": 200.0},
        }
    ]
    shield = Shield(ShieldConfig.from_dict({"criteria": both}))
    z = (
        shield.normalise(np.array([0.0, 5.0, 0.0]))[1],
        shield.normalise(np.array([0.0, 200.0, 0.0]))[1],
    )
    assert risk_parts(shield).local_risk.bounds.tolist() == [[1.0, z[0], z[1]]]


def test_a_snapshot_with_a_negative_peak_is_refused() -> None:
    shield = Shield(ShieldConfig())
    crash_world(shield, 20, seed=1)
    data = shield.snapshot()
    data["local_risk"]["peak"][0] = -1.0
    with pytest.raises(InvalidSnapshot) as error:
        Shield.from_snapshot(data)
    assert error.value.field == "local_risk.peak"


def test_the_peak_round_trips_and_a_snapshot_from_before_it_loads_with_it_to_learn() -> None:
    shield = Shield(ShieldConfig())
    crash_world(shield, 20, seed=1)
    data = shield.snapshot()
    data["local_risk"]["peak"] = np.array([0.01, 0.02, 0.03])
    restored = Shield.from_snapshot(data)
    assert restored.snapshot()["local_risk"]["peak"].tolist() == [0.01, 0.02, 0.03]
    n = data["local_risk"]["dynamics"].shape[0]
    del data["local_risk"]["peak"]
    data["local_risk"]["spread"] = np.zeros((n, 3))  # what it kept instead, per state
    restored = Shield.from_snapshot(data)
    assert not restored.snapshot()["local_risk"]["peak"].any()


def test_the_extent_is_the_union_of_the_boxes_and_survives_a_snapshot() -> None:
    shield = Shield(ShieldConfig())
    crash_world(shield, 20, seed=1)
    extent = risk_parts(shield).local_risk.arrays()[6]
    low, high = shield.snapshot()["local_risk"]["low"], shield.snapshot()["local_risk"]["high"]
    applied = low <= high
    assert np.array_equal(extent[0], np.where(applied, low, np.inf).min(axis=(0, 1)))
    assert np.array_equal(extent[1], np.where(applied, high, -np.inf).max(axis=(0, 1)))
    restored = Shield.from_snapshot(shield.snapshot())
    assert np.array_equal(risk_parts(restored).local_risk.arrays()[6], extent)


def test_a_snapshot_with_a_bad_failure_point_count_is_refused() -> None:
    shield = Shield(ShieldConfig())
    crash_world(shield, 20, seed=1)
    data = shield.snapshot()
    data["local_risk"]["point_counts"][0] = [3, 7]  # next slot beyond the points kept
    with pytest.raises(InvalidSnapshot) as error:
        Shield.from_snapshot(data)
    assert error.value.field == "local_risk.point_counts"


@pytest.mark.parametrize(
    "risk_section",
    [
        {"reach_horizon": -1},
        {"reach_horizon": 5000},
        {"reach_radius": 0.0},
        {"reach_radius": float("nan")},
    ],
)
def test_bad_reach_settings_are_refused_naming_the_field(risk_section: dict[str, Any]) -> None:
    with pytest.raises(InvalidConfig) as error:
        ShieldConfig.from_dict({"risk": risk_section})
    assert error.value.field == f"risk.{next(iter(risk_section))}"


def test_a_configuration_stored_before_the_reach_loads_without_it() -> None:
    stored = ShieldConfig().to_dict()
    stored["version"] = 3
    del stored["risk"]["reach_horizon"], stored["risk"]["reach_radius"]
    assert ShieldConfig.from_stored(stored).risk.reach_horizon == 0
    assert ShieldConfig.from_stored(ShieldConfig().to_dict()).risk.reach_horizon == 40


@pytest.mark.parametrize(
    ("criteria", "observation", "field"),
    [
        (
            [{"name": "c", "direction": "decrease", "bound": {"observation": "speed", "below": 0}}],
            {},
            "criteria.0.bound.observation",
        ),
        (
            [{"name": "c", "direction": "decrease", "bound": {"observation": "headway"}}],
            {},
            "criteria.0.bound.below",
        ),
        (
            [
                {
                    "name": "c",
                    "direction": "decrease",
                    "bound": {"observation": "headway", "below": 5, "above": 5},
                }
            ],
            {},
            "criteria.0.bound.above",
        ),
        (
            [
                {
                    "name": "c",
                    "direction": "decrease",
                    "bound": {"observation": "headway", "below": "near"},
                }
            ],
            {},
            "criteria.0.bound.below",
        ),
        (
            [
                {
                    "name": "c",
                    "direction": "decrease",
                    "bound": {"observation": "headway", "below": 0},
                }
            ],
            {
                "cluster_raw": False,
                "features": [{"name": "gap", "weights": [0, 1, 0], "low": 0, "high": 50}],
            },
            "criteria.0.bound",
        ),
        (
            None,
            {"names": ["x"], "low": [0], "high": [1], "knee": []},
            "criteria.0.bound.observation",
        ),  # the default criteria bound the headway
    ],
)
def test_bad_bounds_are_refused_naming_the_field(
    criteria: list[Any] | None, observation: dict[str, Any], field: str
) -> None:
    data: dict[str, Any] = {"observation": observation}
    if criteria is not None:
        data["criteria"] = criteria
    with pytest.raises(InvalidConfig) as error:
        ShieldConfig.from_dict(data)
    assert error.value.field == field


def test_a_configuration_stored_before_bounds_decides_without_them() -> None:
    stored = ShieldConfig().to_dict()
    stored["version"] = 4
    for criterion in stored["criteria"]:
        del criterion["bound"]
    assert all(c.bound is None for c in ShieldConfig.from_stored(stored).criteria)
    del stored["criteria"]  # every version from 2 on wrote its criteria: damage, refused
    with pytest.raises(InvalidConfig) as raised:
        ShieldConfig.from_stored(stored)
    assert raised.value.field == "criteria"
    assert ShieldConfig.from_stored(ShieldConfig().to_dict()) == ShieldConfig()
