"""Algs. 1-3 and the noise schedule against the worked examples of spec §10-13."""

from __future__ import annotations

import math

import numpy as np
import pytest

from app.core.config import ReviserConfig
from app.core.revisers.paper import OK, inspect, noise_std, risk, search, variant_threshold

COLLISION, LARGE = 0, 1
DIRECTIONS = ["decrease", "increase"]


@pytest.mark.parametrize(
    ("pred", "expected"),
    [
        ([0.9, 0.05, 0.03, 0.02], 0.9),  # E = 1.17
        ([0.4, 0.35, 0.15, 0.10], 0.4),  # E = 1.95
        ([0.10, 0.35, 0.40, 0.15], 0.4),  # order of states does not matter
        ([0.25] * 4, 0.25),  # uniform: E = (n + 1) / 2, every state passes
        ([0.2, 0.35, 0.2, 0.25], 0.25),  # E = 0.35 + 0.5 + 0.6 + 0.8 = 2.25: the second
    ],
)
def test_alg1_worked_examples(pred: list[float], expected: float) -> None:
    x = sorted(pred, reverse=True)
    e = sum((j + 1) * v for j, v in enumerate(x))
    assert variant_threshold(np.array(pred)) == pytest.approx(x[math.floor(e) - 1])
    assert variant_threshold(np.array(pred)) == pytest.approx(expected)


def test_alg1_threshold_never_exceeds_the_maximum() -> None:
    rng = np.random.default_rng(0)
    for _ in range(50):
        p = rng.dirichlet(np.ones(int(rng.integers(1, 30))) * 0.3)
        assert variant_threshold(p) <= p.max()


def flagged(flags: list[int]) -> tuple[np.ndarray, np.ndarray]:
    index = np.flatnonzero(flags)
    return index, np.array(flags)[index]


def test_alg3_any_sees_an_unfavourable_state_that_the_literal_loop_misses() -> None:
    pred = np.full(4, 0.25)  # diffuse: all four states pass the threshold
    flags = flagged([0, 2, 1, 0])  # state 1 large distance, state 2 collision
    threshold = variant_threshold(pred)
    assert inspect(pred, threshold, flags, "any") == COLLISION  # safety first
    assert inspect(pred, threshold, flags, "first_index") == OK  # state 0 is favourable


def test_alg3_peaked_prediction_only_looks_at_the_likely_state() -> None:
    pred = np.array([0.9, 0.05, 0.05])
    assert inspect(pred, variant_threshold(pred), flagged([0, 1, 1]), "any") == OK
    assert inspect(pred, variant_threshold(pred), flagged([2, 1, 0]), "any") == LARGE
    assert inspect(pred, variant_threshold(pred), flagged([2, 1, 0]), "first_index") == LARGE


def test_risk_is_the_predicted_mass_per_criterion() -> None:
    mass = risk(np.array([0.5, 0.2, 0.3]), flagged([1, 0, 1]), 2)
    assert mass == pytest.approx([0.8, 0.0])


def test_alg2_searches_slower_actions_against_a_collision() -> None:
    table = {9: COLLISION, 8: OK}
    final, tried = search(10, COLLISION, DIRECTIONS, 20, False, table.__getitem__)
    assert final == 8
    assert tried == [(9, COLLISION), (8, OK)]


def test_alg2_accepts_a_large_distance_while_fleeing_a_collision() -> None:
    final, _ = search(5, COLLISION, DIRECTIONS, 20, False, {4: LARGE}.__getitem__)
    assert final == 4


def test_alg2_fixed_steps_back_when_the_upward_search_meets_a_collision() -> None:
    table = {6: LARGE, 7: COLLISION}
    assert search(5, LARGE, DIRECTIONS, 20, False, table.__getitem__) == (
        6,
        [(6, LARGE), (7, COLLISION)],
    )
    # the literal loop stops on the action predicted to crash
    assert search(5, LARGE, DIRECTIONS, 20, True, table.__getitem__)[0] == 7


def test_alg2_off_by_one_at_the_hardest_braking() -> None:
    always = {r: COLLISION for r in range(20)}
    assert search(1, COLLISION, DIRECTIONS, 20, False, always.__getitem__)[0] == 0
    assert search(1, COLLISION, DIRECTIONS, 20, True, always.__getitem__)[0] == -1
    assert search(18, LARGE, DIRECTIONS, 20, False, {19: LARGE}.__getitem__)[0] == 19


def test_noise_schedule_of_spec_13() -> None:
    cfg = ReviserConfig()
    assert noise_std(cfg, 2.0, 1) == pytest.approx(math.sqrt(2.0))
    assert noise_std(cfg, 2.0, 1000) == pytest.approx(math.sqrt(2.0))
    assert noise_std(cfg, 2.0, 1200) == pytest.approx(math.sqrt(2.0 / 1.2))
    assert noise_std(cfg, 2.0, 1500) == pytest.approx(math.sqrt(2.0 / 1.5))
