"""Eqs. 3-4 in their three forms: literal counts, stable dense, lazy sparse."""

from __future__ import annotations

import warnings
from typing import Literal

import numpy as np
import pytest

from app.core.belief import Belief, top_k
from app.core.config import TransitionConfig
from app.core.lazy_tpm import LazyTransitions
from app.core.tpm import (
    DenseTransitions,
    grow_counts,
    grow_stable,
    marginal_by_action,
    probabilities,
    update_counts,
    update_stable,
)

EPS = 1e-3


def one_hot(i: int) -> Belief:
    return Belief(np.array([i]), np.array([1.0]))


def test_eqs_3_4_by_hand() -> None:
    # two states, F = F_o-consistent prior; tau = s0, gamma = s1, phi = 0.5
    F, F_o = grow_counts(*grow_counts(np.zeros((0, 0)), np.zeros(0), EPS), EPS)
    assert F == pytest.approx(np.full((2, 2), EPS))
    assert F_o == pytest.approx([2 * EPS, 2 * EPS])
    F, F_o = update_counts(F, F_o, np.array([1.0, 0.0]), np.array([0.0, 1.0]), 0.5)
    assert F == pytest.approx(np.array([[EPS / 2, EPS / 2 + 0.5], [EPS / 2, EPS / 2]]))
    assert F_o == pytest.approx([EPS + 0.5, EPS])
    P = probabilities(F, F_o)
    assert P[0] == pytest.approx([0.0005 / 0.501, 0.5005 / 0.501])
    assert P[1] == pytest.approx([0.5, 0.5])


@pytest.mark.parametrize("backend", ["dense", "lazy"])
def test_backends_reproduce_the_hand_computed_matrix(backend: str) -> None:
    cfg = TransitionConfig(learning_rate=0.5, prior=EPS)
    model = DenseTransitions(2, cfg) if backend == "dense" else LazyTransitions(2, cfg, 10)
    model.add_state()
    model.add_state()
    model.learn_one(one_hot(0), 1, one_hot(1))
    assert model.matrix(1)[0] == pytest.approx([0.0005 / 0.501, 0.5005 / 0.501])
    assert model.matrix(1)[1] == pytest.approx([0.5, 0.5])
    assert model.matrix(0) == pytest.approx(np.full((2, 2), 0.5))  # other action untouched


def test_first_state_gives_one_by_one_matrices() -> None:
    model = LazyTransitions(3, TransitionConfig(), 10)
    model.add_state()
    for a in range(3):
        assert model.matrix(a) == pytest.approx(np.ones((1, 1)))
        assert model.row_mass(a) == pytest.approx([EPS])


@pytest.mark.parametrize("mode", ["prior", "zero_uniform", "zero_identity"])
def test_lazy_equals_dense_equals_literal_on_a_random_history(
    mode: Literal["prior", "zero_uniform", "zero_identity"],
) -> None:
    rng = np.random.default_rng(7)
    cfg = TransitionConfig(learning_rate=0.05, expansion=mode)
    q = 4
    dense, lazy = DenseTransitions(q, cfg), LazyTransitions(q, cfg, 100)
    F = [np.zeros((0, 0))] * q
    F_o = [np.zeros(0)] * q
    prev = None
    for _ in range(400):
        if dense.n_states == 0 or rng.random() < 0.08:
            dense.add_state()
            lazy.add_state()
            F = [grow_counts(f, fo, cfg.prior)[0] for f, fo in zip(F, F_o, strict=True)]
            F_o = [f.sum(axis=1) for f in F]
        n = dense.n_states
        belief = top_k(rng.random(n) ** 6, 5)
        if prev is not None:
            a = int(rng.integers(q))
            dense.learn_one(prev, a, belief)
            lazy.learn_one(prev, a, belief)
            F[a], F_o[a] = update_counts(F[a], F_o[a], prev.dense(n), belief.dense(n), 0.05)
        prev = belief
    assert prev is not None
    for a in range(q):
        assert lazy.matrix(a) == pytest.approx(dense.matrix(a), abs=1e-12)
        assert lazy.row_mass(a) == pytest.approx(dense.F_o[a], rel=1e-9)
        for transpose in (True, False):
            assert lazy.predict(prev, a, transpose) == pytest.approx(
                dense.predict(prev, a, transpose), abs=1e-12
            )
        if mode == "prior":  # the literal Eqs. 3-4 only know epsilon-bar padding
            assert probabilities(F[a], F_o[a]) == pytest.approx(dense.matrix(a), abs=1e-12)


def test_stable_form_growth_matches_counts() -> None:
    F, F_o = grow_counts(np.array([[0.3, 0.1], [0.2, 0.2]]), np.array([0.4, 0.4]), EPS)
    P, P_o = grow_stable(np.array([[0.75, 0.25], [0.5, 0.5]]), np.array([0.4, 0.4]), EPS, "prior")
    assert P == pytest.approx(probabilities(F, F_o))
    assert P_o == pytest.approx(F_o)


@pytest.mark.slow  # long streams: seconds
def test_no_underflow_after_200k_updates() -> None:
    """A row that is never visited again keeps its probabilities in the lazy form."""
    cfg = TransitionConfig(learning_rate=0.01)
    lazy = LazyTransitions(1, cfg, 10)
    for _ in range(3):
        lazy.add_state()
    lazy.learn_one(one_hot(2), 0, one_hot(1))
    for _ in range(200_000):
        lazy.learn_one(one_hot(0), 0, one_hot(1))
    P = lazy.matrix(0)
    assert np.all(np.isfinite(P))
    assert P.sum(axis=1) == pytest.approx(np.ones(3))
    # state 2's single transition, learned 200,000 updates ago, is remembered exactly
    once = np.array([0.99 * EPS, 0.99 * EPS + 0.01, 0.99 * EPS])
    assert P[2] == pytest.approx(once / once.sum())
    # the literal counts of row 2 decay into denormals, where F - phi F stops changing: the
    # row they give is no longer the one learned (here not even a distribution)
    F, F_o = np.full((3, 3), EPS), np.full(3, 3 * EPS)
    F, F_o = update_counts(F, F_o, np.array([0, 0, 1.0]), np.array([0, 1.0, 0]), 0.01)
    for _ in range(200_000):
        F, F_o = update_counts(F, F_o, np.array([1.0, 0, 0]), np.array([0, 1.0, 0]), 0.01)
    with np.errstate(invalid="ignore"):
        literal = probabilities(F, F_o)[2]
    assert not np.allclose(literal, once / once.sum())


@pytest.mark.slow  # long streams: seconds
def test_recursive_estimate_converges_to_the_transition_frequencies() -> None:
    true_P = np.array([[0.7, 0.2, 0.1], [0.1, 0.8, 0.1], [0.3, 0.3, 0.4]])
    rng = np.random.default_rng(0)
    lazy = LazyTransitions(1, TransitionConfig(learning_rate=0.0005), 10)
    for _ in range(3):
        lazy.add_state()
    s = 0
    for _ in range(80_000):
        nxt = int(rng.choice(3, p=true_P[s]))
        lazy.learn_one(one_hot(s), 0, one_hot(nxt))
        s = nxt
    assert lazy.matrix(0) == pytest.approx(true_P, abs=0.05)


def test_update_touches_only_rows_with_mass() -> None:
    P = np.array([[0.5, 0.5], [0.2, 0.8]])
    P_new, F_o = update_stable(
        P, np.array([1.0, 1.0]), np.array([1.0, 0.0]), np.array([1.0, 0.0]), 0.1
    )
    assert P_new[1] == pytest.approx(P[1])
    assert F_o == pytest.approx([1.0, 0.9])
    assert P_new[0] == pytest.approx([0.5 + 0.1 * 0.5, 0.5 - 0.1 * 0.5])


def test_lazy_snapshot_restores_bit_for_bit() -> None:
    rng = np.random.default_rng(1)
    cfg = TransitionConfig()
    lazy = LazyTransitions(3, cfg, 50)
    prev = None
    for _ in range(100):
        if lazy.n_states < 8 and rng.random() < 0.2 or lazy.n_states == 0:
            lazy.add_state()
        belief = top_k(rng.random(lazy.n_states), 4)
        if prev is not None:
            lazy.learn_one(prev, int(rng.integers(3)), belief)
        prev = belief
    assert prev is not None
    copy = LazyTransitions.restore(3, cfg, 50, lazy.snapshot())
    for a in range(3):
        np.testing.assert_array_equal(copy.matrix(a), lazy.matrix(a))
        np.testing.assert_array_equal(copy.predict(prev, a, True), lazy.predict(prev, a, True))


def test_a_belief_state_of_negligible_probability_learns_quietly() -> None:
    """lr * tau underflows to 0 for a subnormal tau: the row keeps its padding, no warning."""
    lazy = LazyTransitions(1, TransitionConfig(), 10)
    lazy.add_state()
    lazy.add_state()
    tiny = Belief(np.array([0, 1]), np.array([1.0, 5e-324]))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        lazy.learn_one(tiny, 0, one_hot(0))
        P = lazy.matrix(0)
    np.testing.assert_allclose(P.sum(axis=1), 1.0)
    np.testing.assert_allclose(P[1], [0.5, 0.5], rtol=1e-12)  # still the padding alone


def test_the_marginal_step_matches_the_loop_bit_for_bit_at_the_experiments_size() -> None:
    """21 actions and 16-state beliefs, as in the car-following experiment: enough terms for
    a change of summation order to show in the last bits (the property test runs 3 actions)."""
    rng = np.random.default_rng(11)
    lazy = LazyTransitions(21, TransitionConfig(), 100)
    prev = None
    for _ in range(3000):
        if lazy.n_states == 0 or lazy.n_states < 30 and rng.random() < 0.02:
            lazy.add_state()
        belief = top_k(rng.random(lazy.n_states) ** 4, 16)
        if prev is not None and prev.index.max() < lazy.n_states:
            lazy.learn_one(prev, int(rng.integers(21)), belief)
        prev = belief
    for _ in range(200):
        belief = top_k(rng.random(lazy.n_states) ** 4, 16)
        np.testing.assert_array_equal(
            lazy.predict_marginal(belief, True), marginal_by_action(lazy, belief, True)
        )


@pytest.mark.slow  # long streams: seconds
def test_memory_follows_what_was_learned_not_the_widest_row() -> None:
    """One state moves to many; the others to one each. The learned entries share one pool,
    so the wide row does not make every row as wide (a padded n x width layout would hold
    n * 1000 entries per action), and every row still predicts as the dense model does."""
    n, q = 1000, 2
    cfg = TransitionConfig()
    lazy, dense = LazyTransitions(q, cfg, n), DenseTransitions(q, cfg)
    for _ in range(n):
        lazy.add_state()
        dense.add_state()
    for j in range(n):  # state 0 moves everywhere, one at a time: its row moves and grows
        lazy.learn_one(one_hot(0), 0, one_hot(j))
        dense.learn_one(one_hot(0), 0, one_hot(j))
    for i in range(1, n):
        lazy.learn_one(one_hot(i), 1, one_hot((i + 1) % n))
        dense.learn_one(one_hot(i), 1, one_hot((i + 1) % n))
    entries = 2 * n  # what was learned
    assert lazy.nbytes() < 400 * entries  # the per-state scales and an amortised pool
    for a in range(q):
        for i in (0, 1, n - 1):
            np.testing.assert_allclose(
                lazy.predict(one_hot(i), a, False), dense.predict(one_hot(i), a, False), rtol=1e-9
            )
    copy = LazyTransitions.restore(q, cfg, n, lazy.snapshot())
    np.testing.assert_array_equal(
        copy.predict(one_hot(0), 0, True), lazy.predict(one_hot(0), 0, True)
    )
