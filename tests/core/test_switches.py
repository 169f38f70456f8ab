"""Every switch of the configuration (the paper's gaps, tagged A1-A16 in app/core/config.py)
changes behaviour where it should: one test each."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
import pytest

from app.core import (
    ActionSpec,
    ClusteringConfig,
    LimitsConfig,
    ReviserConfig,
    Shield,
    ShieldConfig,
    TransitionConfig,
)
from app.core.belief import Belief
from app.core.clustering import EvolvingClusterer
from app.core.lazy_tpm import LazyTransitions
from app.core.revisers.paper import noise_std, predict_ahead
from tests.utils import cliff_config


def one_hot(i: int) -> Belief:
    return Belief(np.array([i]), np.array([1.0]))


def paper_reviser(**options: Any) -> ReviserConfig:
    """The paper's reviser with ``options``: the switches below are its."""
    return ReviserConfig(method="paper", **options)


def shield_with(**sections: Any) -> Shield:
    return Shield(dataclasses.replace(cliff_config(), **sections))


def chain_model(n: int = 2) -> LazyTransitions:
    """Action 0 always leads from state 0 to state 1."""
    model = LazyTransitions(2, TransitionConfig(learning_rate=0.5), 10)
    for _ in range(n):
        model.add_state()
    for _ in range(20):
        model.learn_one(one_hot(0), 0, one_hot(1))
    return model


def test_a1_transpose_propagates_the_belief_along_rows() -> None:
    model = chain_model()
    fixed = predict_ahead(model, one_hot(0), 0, ReviserConfig(transpose=True), 8)
    literal = predict_ahead(model, one_hot(0), 0, ReviserConfig(transpose=False), 8)
    assert fixed == pytest.approx([0.0, 1.0], abs=1e-5)  # from state 0 we go to state 1
    assert fixed.sum() == pytest.approx(1.0)
    assert literal.sum() != pytest.approx(1.0)  # P p: a column, not a distribution


def test_a2_ets_plus_makes_a_state_for_a_novel_outlier_and_ets2004_does_not() -> None:
    stream = [0.0, 0.02, 0.04, 1.0]
    counts = {}
    for rule in ("ets_plus", "ets2004"):
        c = EvolvingClusterer(ClusteringConfig(creation_rule=rule), 1, 10)
        for z in stream:
            c.learn_one(np.array([z]))
        counts[rule] = c.n_states
    assert counts == {"ets_plus": 2, "ets2004": 1}


def test_a3_pad_learns_the_transition_into_a_brand_new_state() -> None:
    rows = {}
    for mode in ("skip", "pad"):
        shield = shield_with(transitions=TransitionConfig(on_new_state=mode))
        shield.step([0.0], 0.5)
        shield.step([0.0], 0.5)
        assert shield.step([1.0], 0.5).new_state
        rows[mode] = shield.transitions.matrix(12)[0]
    # skip: state 1 holds only the padding of the expansion, eps / (F_o,0 + eps), after one
    # 0 -> 0 update: F_o,0 = (1 - phi) eps + phi
    f_o = 0.99 * 1e-3 + 0.01
    assert rows["skip"][1] == pytest.approx(1e-3 / (f_o + 1e-3))
    assert rows["pad"][1] > rows["skip"][1] + 0.005  # pad: 0 -> 1 was learned too


def test_a4_overwritten_flags_lift_at_the_next_uneventful_visit() -> None:
    shield = shield_with(reviser=paper_reviser(flags="overwrite"))
    shield.step([0.9], None, event="collision", done=True)
    assert int(shield.flags.flags[0]) == 1
    shield.step([0.9], 0.0)
    assert int(shield.flags.flags[0]) == 0


def test_a4_rate_flags_follow_the_share_of_failures_among_entries() -> None:
    """Count-based flags (A4 c): a state is flagged while its failures are frequent enough
    among the streams that came into it; each criterion counts on its own."""
    shield = shield_with(reviser=paper_reviser(flags="rate", flag_min_rate=0.1))
    shield.step([0.9], None, event="large_distance", done=True)  # 1 failure, 1 entry
    assert shield.flags.flags[0] == 2
    for _ in range(9):
        shield.step([0.9], 0.0, done=True)  # a stream of one step: an entry each
    assert shield.flags.flags[0] == 2  # 1 failure in 10 entries: exactly 10%
    shield.step([0.9], 0.0, done=True)
    assert shield.flags.flags[0] == 0  # 1 in 11: the busy state is favourable again
    shield.step([0.9], None, event="collision", done=True)
    assert shield.flags.flags[0] == 0  # each criterion on its own: 1 in 12
    shield.step([0.9], None, event="collision", done=True)
    assert shield.flags.flags[0] == 1  # 2 collisions in 13
    assert shield.state_view(0)["failures"] == {"collision": 2, "large_distance": 1}


def test_a4_rate_flags_are_not_diluted_by_a_long_stay() -> None:
    """A crash after a long stay in one state flags it (1 crash in 21 recognitions but 1
    entry), and the flag lifts only as streams keep coming into the state without failing."""
    shield = shield_with(reviser=paper_reviser(flag_min_rate=0.1))
    for _ in range(20):
        shield.step([1.0], 0.0)
    shield.step([1.0], None, event="collision", done=True)
    assert int(shield.flags.flags[0]) == 1
    assert shield.state_view(0)["visits"] == 21 and shield.state_view(0)["entries"] == 1

    for _ in range(9):  # in and out again: the stream's first step is an entry too
        shield.step([0.0], 0.0)
        shield.step([1.0], 0.0)
    assert shield.n_states == 2 and shield.states()["entries"].tolist() == [10, 9]
    assert shield.flags.flags[0] == 1  # 1 crash in 10 entries: exactly 10%
    shield.step([0.0], 0.0)
    shield.step([1.0], 0.0)
    assert shield.flags.flags[0] == 0  # 1 in 11


def diffuse_prediction_shield(rule: str) -> Shield:
    """State 0 favourable, state 1 flagged; untried actions predict 50/50."""
    shield = shield_with(reviser=paper_reviser(inspect=rule, activate_after_episodes=0))
    shield.step([0.0], 0.0)
    shield.step([0.0], 0.0)
    shield.step([1.0], None, event="collision", done=True)
    return shield


def test_a5_any_inspects_every_likely_state_and_first_index_only_the_first() -> None:
    assert diffuse_prediction_shield("any").step([0.0], 1.5).reason == "revised_safety"
    assert diffuse_prediction_shield("first_index").step([0.0], 1.5).reason == "pass"


def test_a6_literal_search_runs_below_the_hardest_braking() -> None:
    # a one-state model flagged for collision: every action is predicted to collide
    actions = {}
    for mode in ("fixed", "literal"):
        shield = shield_with(
            reviser=paper_reviser(search=mode, activate_after_episodes=0, noise="std", noise_k=1e6)
        )
        for _ in range(4):  # four episodes: the noise std is 2 / 4e6, negligible
            shield.step([1.0], None, event="collision", done=True)
        decision = shield.step([1.0], 1.0)
        assert [c.bin for c in decision.candidates] == list(range(14, -1, -1))
        actions[mode] = decision.action
    assert actions["fixed"] == pytest.approx(-1.9)  # bin 0, the hardest braking
    assert actions["literal"] == -2.0  # bin "-1" decodes to -2.1 and is clipped


def test_a7_noise_is_a_variance_or_a_standard_deviation() -> None:
    assert noise_std(ReviserConfig(noise="variance"), 2.0, 1) == pytest.approx(2.0**0.5)
    assert noise_std(ReviserConfig(noise="std"), 2.0, 1) == pytest.approx(2.0)


@pytest.mark.parametrize(("event", "proposal"), [("collision", -2.0), ("large_distance", 2.0)])
def test_one_sided_revisions_never_go_past_the_proposal_the_wrong_way(
    event: str, proposal: float
) -> None:
    """A one-state model flagged for ``event`` revises every step and finds no way out: Alg. 2
    returns the extreme bin's midpoint plus noise (std 1.41 here), which against a collision
    brakes less than full braking half the time; ``one_sided`` keeps the proposal there."""
    applied = {}
    for one_sided in (False, True):
        shield = shield_with(reviser=paper_reviser(activate_after_episodes=0, one_sided=one_sided))
        for _ in range(4):
            shield.step([1.0], None, event=event, done=True)
        decisions = [shield.step([1.0], proposal) for _ in range(200)]
        assert all(d.revised for d in decisions)
        applied[one_sided] = np.array([d.action for d in decisions])
    toward = np.sign(proposal)  # the wrong way: faster against a collision, slower behind
    assert (toward * (applied[False] - proposal) < 0).mean() > 0.3
    assert (applied[True] == proposal).all()


def test_a8_the_transition_is_learned_under_the_executed_or_the_proposed_action() -> None:
    changed = {}
    for source in ("executed", "proposed"):
        shield = shield_with(transitions=TransitionConfig(action_source=source))
        shield.step([0.5], 0.0)
        state = shield.streams["0"]
        state.applied_bin, state.proposed_bin = 3, 17  # the reviser changed bin 17 into bin 3
        before = [shield.transitions.matrix(a).copy() for a in range(20)]
        shield.step([0.5], 0.0)
        changed[source] = [
            a for a in range(20) if not np.array_equal(before[a], shield.transitions.matrix(a))
        ]
    assert changed == {"executed": [3], "proposed": [17]}


def test_a9_spread_definitions_differ() -> None:
    variances = {}
    for spread in ("radius", "member_variance", "ets2004"):
        c = EvolvingClusterer(ClusteringConfig(epsilon=0.3, spread=spread), 1, 10)
        for z in (0.0, 0.1, 0.05):  # 0.1 joins state 0, 0.05 then moves it
            c.learn_one(np.array([z]))
        variances[spread] = float(c.variances()[0])
    assert variances == pytest.approx(
        {
            "radius": (0.7 * 0.3 + 0.3 * np.sqrt(0.01 / 2)) ** 2,  # r^2 after one assignment
            "member_variance": 0.01 / 2,  # scatter / N
            "ets2004": 0.3**2 / 4,  # eTS-2004 membership exp(-4 d^2 / r^2)
        }
    )


@pytest.mark.parametrize(
    ("mode", "new_column", "new_row"),
    [
        ("prior", "positive", [1 / 3] * 3),
        ("zero_uniform", "zero", [1 / 3] * 3),
        ("zero_identity", "zero", [0.0, 0.0, 1.0]),
    ],
)
def test_a10_expansion_values(mode: str, new_column: str, new_row: list[float]) -> None:
    model = LazyTransitions(1, TransitionConfig(expansion=mode), 10)  # type: ignore[arg-type]
    for _ in range(2):
        model.add_state()
    model.learn_one(one_hot(0), 0, one_hot(1))
    model.add_state()
    P = model.matrix(0)
    assert (P[0, 2] > 0) == (new_column == "positive")
    assert P[2] == pytest.approx(new_row)


def test_a11_single_product_ignores_the_horizon_beyond_two_steps() -> None:
    model = chain_model(3)
    model.learn_one(one_hot(1), 1, one_hot(2))
    preds = {
        (mode, k): predict_ahead(model, one_hot(0), 0, ReviserConfig(multi_step=mode, horizon=k), 8)
        for mode in ("iterate", "single")
        for k in (2, 3)
    }
    np.testing.assert_array_equal(preds["iterate", 2], preds["single", 2])
    np.testing.assert_array_equal(preds["single", 2], preds["single", 3])
    assert not np.allclose(preds["iterate", 3], preds["single", 3])


def test_a13_across_episodes_learns_the_reset_transition() -> None:
    changed = {}
    for across in (False, True):
        shield = shield_with(transitions=TransitionConfig(across_episodes=across))
        shield.step([0.2], 1.5)
        assert shield.step([0.2], None, done=True).step == 1
        before = shield.transitions.matrix(17).copy()
        shield.step([0.2], 0.0)
        changed[across] = not np.array_equal(before, shield.transitions.matrix(17))
    assert changed == {False: False, True: True}


def test_a16_reset_forgets_what_a_moved_state_had_learned() -> None:
    rows = {}
    for mode in ("keep", "reset"):
        shield = shield_with(transitions=TransitionConfig(on_replace=mode))
        shield.step([1.0], 0.0)
        shield.step([1.0], 0.0)
        assert shield.step([0.0], -1.5).new_state  # state 1, left under bin 2 next
        shield.step([0.02], 1.5)  # state 1 moves; learns 1 -> 1 under bin 2
        shield.step([0.04], 1.5)  # state 1 moves again
        assert shield.clusterer.centres[1, 0] == pytest.approx(0.04)
        rows[mode] = shield.transitions.matrix(2)[1]
    assert rows["keep"][1] > 0.9
    assert rows["reset"] == pytest.approx([0.5, 0.5])


def test_a16_reset_needs_the_lazy_backend() -> None:
    with pytest.raises(ValueError):
        Shield(
            ShieldConfig(
                transitions=TransitionConfig(on_replace="reset"),
                limits=LimitsConfig(tpm_backend="dense"),
            )
        )


def test_paper_literal_preset_takes_the_literal_reading_everywhere() -> None:
    literal = ShieldConfig.paper_literal()
    assert literal.reviser.transpose is False
    assert literal.reviser.inspect == "first_index"
    assert literal.reviser.search == "literal"
    assert literal.reviser.multi_step == "single"
    assert literal.reviser.flags == "overwrite"
    assert literal.reviser.one_sided is False  # not in the paper
    assert literal.clustering.creation_rule == "ets2004"
    assert literal.transitions.action_source == "proposed"
    assert literal.transitions.across_episodes is True
    # the paper's values stay
    assert (literal.clustering.rho, literal.clustering.epsilon) == (0.7, 0.3)
    assert literal.reviser.activate_after_episodes == 50


def test_the_revision_noise_follows_the_width_of_the_action_range() -> None:
    """The same trap on [-2, 2] and on [0, 4]: the paper's V uses the half-width (2 in both),
    so the revisions spread alike around their bins, wherever the range lies."""
    spreads = []
    for low, high in ((-2.0, 2.0), (0.0, 4.0)):
        config = dataclasses.replace(
            cliff_config(activate_after_episodes=0, one_sided=False),
            action=ActionSpec(low=low, high=high),
        )
        shield = Shield(config)
        for _ in range(4):
            shield.step([1.0], None, event="collision", done=True)
        applied = [shield.step([1.0], low + 2.0).action for _ in range(300)]
        spreads.append(float(np.std([a for a in applied if a is not None])))
    assert spreads[0] == pytest.approx(spreads[1])
