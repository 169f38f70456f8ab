from __future__ import annotations

import math

import numpy as np
import pytest

from app.core.belief import recognise, top_k
from tests.core import reference


def test_eq1_on_a_hand_computed_case() -> None:
    d2 = np.array([0.25, 0.25, 1.0])
    var = np.array([0.05, 0.09, 0.09])
    eta = [math.exp(-0.25 / 0.05), math.exp(-0.25 / 0.09), math.exp(-1.0 / 0.09)]
    belief = recognise(d2, var, k=3)
    assert belief.index.tolist() == [0, 1, 2]
    assert belief.prob == pytest.approx([e / sum(eta) for e in eta])
    assert belief.argmax() == 1


def test_far_from_every_state_still_gives_a_distribution() -> None:
    # the literal exp(-d^2 / var) underflows to 0 for both states: 0 / 0
    d2 = np.array([900.0, 1000.0])
    var = np.array([1e-4, 1e-4])
    assert np.exp(-d2 / var).sum() == 0.0
    belief = recognise(d2, var, k=2)
    assert belief.prob.sum() == pytest.approx(1.0)
    assert belief.argmax() == 0


def test_truncation_keeps_the_k_most_likely_states_in_index_order() -> None:
    d2 = np.array([0.5, 0.1, 0.9, 0.05, 0.3])
    belief = recognise(d2, np.full(5, 0.1), k=2)
    assert belief.index.tolist() == [1, 3]
    assert belief.prob.sum() == pytest.approx(1.0)
    exact = recognise(d2, np.full(5, 0.1), k=5)
    assert exact.dense(5)[[1, 3]] / exact.dense(5)[[1, 3]].sum() == pytest.approx(belief.prob)


def test_ties_resolve_to_the_lowest_index() -> None:
    belief = recognise(np.array([0.2, 0.1, 0.1]), np.ones(3), k=3)
    assert belief.argmax() == 1


def test_top_k_renormalises_and_drops_zeros() -> None:
    b = top_k(np.array([0.0, 0.2, 0.6, 0.2]), 3)
    assert b.index.tolist() == [1, 2, 3]
    assert b.prob == pytest.approx([0.2, 0.6, 0.2])


@pytest.mark.parametrize("seed", range(10))
def test_the_compiled_recognition_gives_the_numpy_reading(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 60))
    d2 = rng.uniform(0, 2, n) * rng.choice([1e-3, 1.0, 100.0])
    var = rng.uniform(1e-4, 0.1, n)
    for k in (1, 4, 16):
        belief = recognise(d2, var, k)
        index, prob = reference.recognise(d2, var, k)
        np.testing.assert_array_equal(belief.index, index)
        np.testing.assert_array_equal(belief.prob, prob)
