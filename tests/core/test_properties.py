"""Invariants on random inputs (Hypothesis, seeded and bounded by the project profile)."""

from __future__ import annotations

from typing import Literal, cast

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from app.core import LimitsConfig, Shield, ShieldConfig, TransitionConfig
from app.core.belief import Belief, recognise, top_k
from app.core.lazy_tpm import LazyTransitions
from app.core.tpm import (
    DenseTransitions,
    TransitionModel,
    grow_counts,
    marginal_by_action,
    probabilities,
    update_counts,
)
from tests.core.checks import check_all
from tests.utils import assert_same

finite = st.floats(0.0, 1e6, allow_nan=False, allow_infinity=False)
observation = st.tuples(st.floats(0, 32), st.floats(0, 210), st.floats(0, 32))
step = st.tuples(
    observation,
    st.floats(-2.5, 2.5),
    st.booleans(),
    st.sampled_from([None, "collision", "large_distance"]),
)
streams = st.lists(step, min_size=1, max_size=60)
Step = tuple[tuple[float, float, float], float, bool, str | None]
Op = str | tuple[int, int, int]  # "grow", or (action, seed, seed)
Expansion = Literal["prior", "zero_uniform", "zero_identity"]


def feed(shield: Shield, steps: list[Step]) -> list[tuple[object, ...]]:
    out: list[tuple[object, ...]] = []
    for z, a, done, event in steps:
        d = shield.step(list(z), None if done else a, event=event, done=done)
        out.append((d.action, d.reason, d.state, d.n_states, d.threshold))
    return out


@given(
    arrays(np.float64, st.integers(1, 40), elements=finite),
    st.integers(1, 50),
    st.floats(1e-4, 10.0),
)
def test_beliefs_sum_to_one(d2: np.ndarray, k: int, var: float) -> None:
    belief = recognise(d2, np.full(d2.shape, var), k)
    assert np.isclose(belief.prob.sum(), 1.0)
    assert np.all(belief.prob >= 0) and belief.index.size <= k
    assert np.all(np.diff(belief.index) > 0)


ops = st.lists(
    st.one_of(
        st.just("grow"), st.tuples(st.integers(0, 2), st.integers(0, 10**6), st.integers(0, 10**6))
    ),
    min_size=1,
    max_size=40,
)


def play(op: Op, *models: TransitionModel) -> tuple[int, Belief, Belief] | None:
    """One of ``ops`` on every model: a new state, or a transition between two random
    beliefs under an action (returned)."""
    if op == "grow":
        for model in models:
            model.add_state()
        return None
    a, s1, s2 = cast(tuple[int, int, int], op)
    n = models[0].n_states
    tau = top_k(np.random.default_rng(s1).random(n), 4)
    gamma = top_k(np.random.default_rng(s2).random(n), 4)
    for model in models:
        model.learn_one(tau, a, gamma)
    return a, tau, gamma


@given(ops, st.sampled_from(["prior", "zero_uniform", "zero_identity"]), st.floats(0.001, 0.5))
def test_tpm_rows_stay_distributions_and_forms_agree(
    ops_list: list[Op], mode: Expansion, lr: float
) -> None:
    cfg = TransitionConfig(learning_rate=lr, expansion=mode)
    lazy, dense = LazyTransitions(3, cfg, 100), DenseTransitions(3, cfg)
    F, F_o = [np.zeros((0, 0))] * 3, [np.zeros(0)] * 3
    for op in ["grow", *ops_list]:
        learned = play(op, lazy, dense)
        if learned is None:
            F = [grow_counts(f, fo, cfg.prior)[0] for f, fo in zip(F, F_o, strict=True)]
            F_o = [f.sum(axis=1) for f in F]
            continue
        a, tau, gamma = learned
        n = lazy.n_states
        F[a], F_o[a] = update_counts(F[a], F_o[a], tau.dense(n), gamma.dense(n), lr)
    for a in range(3):
        P = lazy.matrix(a)
        assert np.all(P >= 0) and np.allclose(P.sum(axis=1), 1.0)
        np.testing.assert_allclose(P, dense.matrix(a), atol=1e-12)
        if mode == "prior":
            np.testing.assert_allclose(probabilities(F[a], F_o[a]), P, atol=1e-12)


@pytest.mark.slow  # Hypothesis: seconds
@given(
    ops,
    st.sampled_from(["prior", "zero_uniform", "zero_identity"]),
    st.lists(st.integers(0, 40), max_size=3),
)
def test_lazy_scales_kept_per_row_equal_a_fresh_computation(
    ops_list: list[Op], mode: Expansion, resets: list[int]
) -> None:
    """The row scales that learning updates in place are what a restore computes anew."""
    cfg = TransitionConfig(expansion=mode, on_replace="reset")
    lazy = LazyTransitions(3, cfg, 100)
    for op in ["grow", *ops_list]:
        play(op, lazy)
    for state in resets:
        lazy.reset_row(state % lazy.n_states)
    fresh = LazyTransitions.restore(3, cfg, 100, lazy.snapshot())
    belief = top_k(np.random.default_rng(0).random(lazy.n_states), 4)
    for a in range(3):
        for transpose in (True, False):
            np.testing.assert_array_equal(
                fresh.predict(belief, a, transpose), lazy.predict(belief, a, transpose)
            )
        np.testing.assert_array_equal(fresh.row_mass(a), lazy.row_mass(a))


@given(
    ops,
    st.sampled_from(["prior", "zero_uniform", "zero_identity"]),
    st.integers(1, 6),
    st.integers(0, 10**6),
)
def test_the_marginal_step_of_every_action_at_once_is_their_mean_bit_for_bit(
    ops_list: list[Op], mode: Expansion, k: int, seed: int
) -> None:
    """The two-step prediction's one pass over all actions gives the numbers of Eq. 7 as
    written (Eq. 5 per action, summed in action order), so that runs do not change with it;
    and the dense backend's marginal within round-off."""
    cfg = TransitionConfig(expansion=mode)
    lazy, dense = LazyTransitions(3, cfg, 100), DenseTransitions(3, cfg)
    for op in ["grow", *ops_list]:
        play(op, lazy, dense)
    belief = top_k(np.random.default_rng(seed).random(lazy.n_states), k)
    for transpose in (True, False):
        marginal = lazy.predict_marginal(belief, transpose)
        np.testing.assert_array_equal(marginal, marginal_by_action(lazy, belief, transpose))
        np.testing.assert_allclose(
            marginal, dense.predict_marginal(belief, transpose), rtol=1e-9, atol=1e-12
        )


@pytest.mark.slow  # Hypothesis: seconds
@given(streams)
def test_invariants_hold_on_any_stream(steps: list[Step]) -> None:
    shield = Shield(ShieldConfig(limits=LimitsConfig(belief_top_k=4)))
    sizes = []
    for z, a, done, event in steps:
        shield.step(list(z), None if done else a, event=event, done=done)
        sizes.append(shield.n_states)
        check_all(shield)
    assert sizes == sorted(sizes)


@pytest.mark.slow  # Hypothesis: seconds
@given(streams, streams)
def test_snapshot_restore_gives_the_same_decisions(first: list[Step], then: list[Step]) -> None:
    shield = Shield(ShieldConfig())
    feed(shield, first)
    restored = Shield.from_snapshot(shield.snapshot())
    assert feed(restored, then) == feed(shield, then)
    assert_same(restored.snapshot(), shield.snapshot())


@pytest.mark.slow  # Hypothesis: seconds
@given(streams, st.integers(0, 2**32))
def test_same_seed_same_model(steps: list[Step], seed: int) -> None:
    config = ShieldConfig.from_dict({"reviser": {"seed": seed, "activate_after_episodes": 0}})
    a, b = Shield(config), Shield(config)
    assert feed(a, steps) == feed(b, steps)
    assert_same(a.snapshot(), b.snapshot())


@pytest.mark.slow  # Hypothesis: seconds
@given(streams, observation, st.floats(-2, 2))
def test_learn_false_and_inputs_are_left_untouched(
    steps: list[Step], z: tuple[float, float, float], a: float
) -> None:
    shield = Shield()
    feed(shield, steps)
    before = shield.snapshot()
    obs = np.array(z)
    shield.step(obs, a, learn=False)
    assert_same(shield.snapshot(), before)
    shield.step(obs, a)
    np.testing.assert_array_equal(obs, np.array(z))  # the caller's array is not mutated


@given(
    st.tuples(st.floats(-50, 50), st.floats(-20, 400), st.floats(-50, 50)), st.floats(0.5, 100.0)
)
def test_a_knee_maps_observations_one_to_one_and_stretches_the_close_range(
    z: tuple[float, float, float], knee: float
) -> None:
    linear = Shield(ShieldConfig.from_dict({"observation": {"knee": []}}))
    curved = Shield(ShieldConfig.from_dict({"observation": {"knee": [0.0, knee, 0.0]}}))
    x = np.array(z)
    assert np.allclose(curved.physical(curved.normalise(x)), x, rtol=1e-9, atol=1e-9)
    assert curved.normalise(x)[[0, 2]].tolist() == linear.normalise(x)[[0, 2]].tolist()
    # Below the knee one metre of headway spans more of the clustering space than it does
    # linearly; far above it, as much.
    gap = np.array([0.0, 1.0, 0.0])
    near, far = np.array([10.0, 0.0, 10.0]), np.array([10.0, 50.0 + 20 * knee, 10.0])
    assert curved.normalise(near + gap)[1] - curved.normalise(near)[1] > 1 / 50
    far_gap = curved.normalise(far + gap)[1] - curved.normalise(far)[1]
    assert far_gap == pytest.approx(1 / 50, rel=1e-9)
