"""One step of the shield: its order (docs/api.md, "One step"), streams, bad input, snapshots,
determinism."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
import pytest

from app.core import (
    ActionSpec,
    InvalidAction,
    InvalidConfig,
    InvalidObservation,
    InvalidSnapshot,
    LimitsConfig,
    RiskConfig,
    Shield,
    ShieldConfig,
    ShieldError,
    UnknownCriterion,
)
from tests.utils import assert_same, cliff_config, random_stream, run_cliff


def test_first_steps_create_states_and_start_cold() -> None:
    shield = Shield()
    first = shield.step([10.0, 50.0, 12.0], 0.5)
    assert first.new_state and first.n_states == 1 and first.state == 0
    assert first.reason == "cold_start" and first.action == 0.5 and not first.revised
    assert first.threshold is None
    assert first.risk == {"collision": 0.0, "large_distance": 0.0}
    assert (first.episode, first.step, first.model_version, first.stream) == (0, 0, 1, "0")
    second = shield.step([10.1, 50.0, 12.0], 0.5)
    assert second.step == 1 and second.model_version == 2


def test_done_closes_the_episode_and_forgets_the_stream() -> None:
    shield = Shield()
    shield.step([10.0, 50.0, 12.0], 0.5)
    end = shield.step([10.0, 0.0, 12.0], None, event="collision", done=True)
    assert end.action is None and end.reason == "done"
    assert end.episode == 1 and shield.counters.episodes == 1
    assert "0" not in shield.streams
    assert shield.flags.flags[end.state] == 1  # collision, the highest priority


def test_streams_keep_their_own_previous_step() -> None:
    shield = Shield()
    shield.step([10.0, 50.0, 12.0], 0.5, stream="a")
    shield.step([20.0, 150.0, 25.0], -0.5, stream="b")
    step_a = shield.step([10.0, 50.0, 12.0], 0.5, stream="a")
    assert step_a.step == 1 and shield.streams["b"].step == 1
    assert shield.streams["a"].proposed_bin == 12 and shield.streams["b"].proposed_bin == 7


def test_the_transition_is_learned_under_the_applied_action() -> None:
    shield = Shield()
    z = [10.0, 50.0, 12.0]
    shield.step(z, 0.5)
    before = [shield.transitions.matrix(a).copy() for a in range(20)]
    shield.step(z, 0.5, applied_action=-1.95)  # the vehicle really braked at t-1
    changed = [a for a in range(20) if not np.array_equal(shield.transitions.matrix(a), before[a])]
    assert changed == [0]


def test_learn_false_changes_nothing_not_even_the_noise_generator() -> None:
    shield = Shield(cliff_config(activate_after_episodes=2))
    run_cliff(shield, 20, seed=1)
    snapshot = shield.snapshot()
    for proposed in (-1.0, 1.5, 1.9):
        shield.step([0.5], proposed, learn=False)
        shield.step([0.95], None, done=True, learn=False)
    assert_same(shield.snapshot(), snapshot)


def test_learn_false_answers_like_learning_would_on_a_known_state() -> None:
    shield = Shield(cliff_config(activate_after_episodes=2))
    run_cliff(shield, 40, seed=1)
    what_if = shield.step([0.5], 1.9, learn=False)
    real = shield.step([0.5], 1.9)
    assert what_if.verdict == real.verdict == "collision"
    assert what_if.action == real.action and what_if.revised


def test_shadow_learns_but_returns_the_proposed_action() -> None:
    shield = Shield(cliff_config(activate_after_episodes=2))
    run_cliff(shield, 40, seed=1)
    decision = shield.step([0.5], 1.9, shadow=True)
    assert decision.shadow and decision.revised and decision.reason == "revised_safety"
    assert decision.action == 1.9
    assert decision.suggested is not None and decision.suggested < 1.0
    assert shield.streams["0"].applied_bin == 19


def test_reviser_waits_for_the_activation_episode() -> None:
    shield = Shield(cliff_config(activate_after_episodes=30))
    run_cliff(shield, 29, seed=2)
    assert shield.step([0.5], 1.9).reason == "inactive"
    shield.step([0.95], None, event="collision", done=True)
    assert shield.step([0.5], 1.9).reason == "revised_safety"
    assert shield.counters.interventions["collision"] == 1


BAD_STEPS = [
    (dict(observation=[1.0, 2.0], action=0.0), InvalidObservation, "observation"),
    (dict(observation=[1.0, math.nan, 2.0], action=0.0), InvalidObservation, "observation"),
    (dict(observation=[1.0, math.inf, 2.0], action=0.0), InvalidObservation, "observation"),
    (dict(observation=["a", 1.0, 2.0], action=0.0), InvalidObservation, "observation"),
    (dict(observation=[1.0, 1e160, 2.0], action=0.0), InvalidObservation, "observation"),
    (dict(observation=[-1e300, 1.0, 2.0], action=0.0), InvalidObservation, "observation"),
    (dict(observation=[1.0, 50.0, 2.0], action=math.nan), InvalidAction, "action"),
    (dict(observation=[1.0, 50.0, 2.0], action=None), InvalidAction, "action"),
    (dict(observation=[1.0, 50.0, 2.0], action="fast"), InvalidAction, "action"),
    (dict(observation=[1.0, 50.0, 2.0], action=0.0, event="meteor"), UnknownCriterion, "event"),
    (
        dict(observation=[1.0, 50.0, 2.0], action=0.0, applied_action=math.inf),
        InvalidAction,
        "applied_action",
    ),
    (dict(observation=[1.0, 50.0, 2.0], action=0.0, stream=""), ShieldError, "stream"),
]


@pytest.mark.parametrize(("step", "error", "field"), BAD_STEPS)
def test_bad_input_raises_a_typed_error_and_changes_nothing(
    step: dict[str, object], error: type[ShieldError], field: str
) -> None:
    shield = Shield()
    for z, a, done in random_stream(0, 30):
        shield.step(z, a, done=done)
    before = shield.snapshot()
    observation = step.pop("observation")
    action = step.pop("action")
    with pytest.raises(error) as raised:
        shield.step(observation, action, **step)  # type: ignore[arg-type]
    assert raised.value.field == field
    assert_same(shield.snapshot(), before)


def test_out_of_range_actions_are_clipped_or_rejected_by_configuration() -> None:
    assert Shield().step([1.0, 50.0, 2.0], 7.0).action == 2.0
    strict = Shield(ShieldConfig(action=ActionSpec(out_of_range="reject")))
    with pytest.raises(InvalidAction) as raised:
        strict.step([1.0, 50.0, 2.0], 7.0)
    assert raised.value.field == "action"
    assert strict.n_states == 0


def test_same_seed_same_stream_gives_bit_identical_models_and_decisions() -> None:
    a, b = Shield(cliff_config(seed=5)), Shield(cliff_config(seed=5))
    _, pairs_a = run_cliff(a, 60, seed=3)
    _, pairs_b = run_cliff(b, 60, seed=3)
    assert pairs_a == pairs_b
    assert_same(a.snapshot(), b.snapshot())
    c = Shield(cliff_config(seed=6))
    _, pairs_c = run_cliff(c, 60, seed=3)
    assert pairs_c != pairs_a  # the revision noise comes from the seed


def test_snapshot_restore_makes_the_same_decisions() -> None:
    shield = Shield(cliff_config(activate_after_episodes=5))
    run_cliff(shield, 30, seed=4)
    copy = Shield.from_snapshot(shield.snapshot())
    assert_same(copy.snapshot(), shield.snapshot())
    _, original = run_cliff(shield, 30, seed=9)
    _, restored = run_cliff(copy, 30, seed=9)
    assert restored == original
    assert_same(copy.snapshot(), shield.snapshot())


def version_2(config: dict[str, Any]) -> dict[str, Any]:
    """A configuration as version 2 of the stored format wrote it: the counted risk model's
    settings, the local model named, and no reach (it came with version 4)."""
    old = {key: dict(value) if isinstance(value, dict) else value for key, value in config.items()}
    old["version"] = 2
    del old["risk"]["reach_horizon"], old["risk"]["reach_radius"]
    old["risk"].update(model="local", prior_safe=1.0, refresh_steps=500)
    old["limits"]["outcome_log"] = 200_000
    return old


def version_1(config: dict[str, Any]) -> dict[str, Any]:
    """A configuration as version 1 of the stored format wrote it: no ``version``, with the
    switches removed since at the values whose behaviour remains (the risk model of version 1
    was the counted one: ``risk.model`` missing)."""
    old = version_2(config)
    del old["version"], old["risk"]["model"]
    old["observation"]["knee_shape"] = "double"
    old["clustering"]["failure_states"] = False
    old["reviser"].update(flag_rate_per="entry", failure_centres=False, noise_side="both")
    old["risk"].update(precursor_steps=0, precursor_spacing=0.5)
    return old


def test_a_version_1_snapshot_restores_and_decides_as_it_did() -> None:
    """A field added off and turned on by default later (``reviser.one_sided``): a snapshot
    written before it existed lacks it and must go on deciding as it did; the removed
    switches at their remaining values drop out; the flags' entries, not yet counted then,
    count from the restore on."""
    shield = Shield(cliff_config(activate_after_episodes=5, one_sided=False))
    run_cliff(shield, 30, seed=4)
    old = shield.snapshot()
    old["config"] = version_1(old["config"])
    del old["config"]["reviser"]["one_sided"], old["flags"]["entries"]
    copy = Shield.from_snapshot(old)
    assert copy.config == shield.config
    assert copy.flags.entries.tolist() == [0] * copy.n_states
    _, original = run_cliff(shield, 30, seed=9)
    _, restored = run_cliff(copy, 30, seed=9)
    assert restored == original
    assert copy.flags.entries.sum() > 0


@pytest.mark.parametrize(
    ("section", "name", "value"),
    [
        ("observation", "knee_shape", "log"),
        ("clustering", "failure_states", True),
        ("reviser", "failure_centres", True),
        ("reviser", "noise_side", "away"),
        ("reviser", "flag_rate_per", "recognition"),
        ("risk", "precursor_steps", 4),
    ],
)
def test_a_stored_configuration_with_a_removed_switch_is_refused_by_name(
    section: str, name: str, value: Any
) -> None:
    old = version_1(ShieldConfig.paper().to_dict())
    assert ShieldConfig.from_stored(old) == ShieldConfig.paper()
    old[section][name] = value
    with pytest.raises(InvalidConfig) as raised:
        ShieldConfig.from_stored(old)
    assert raised.value.field == f"{section}.{name}"
    snapshot = Shield(ShieldConfig.paper()).snapshot()
    snapshot["config"] = old
    with pytest.raises(InvalidSnapshot) as refused:
        Shield.from_snapshot(snapshot)
    assert refused.value.field == f"config.{section}.{name}"


def test_a_version_1_configuration_lacking_later_fields_keeps_their_first_values() -> None:
    old = version_1(ShieldConfig.paper().to_dict())
    for section, name in (
        ("reviser", "method"),
        ("reviser", "flag_min_rate"),
        ("reviser", "flag_rate_per"),
        ("observation", "knee"),
        ("observation", "knee_shape"),
    ):
        del old[section][name]
    old["reviser"]["flags"] = "overwrite"  # flags per recognition mattered only under "rate"
    stored = ShieldConfig.from_stored(old)
    assert (stored.reviser.method, stored.reviser.flag_min_rate) == ("paper", 0.002)
    assert stored.observation.knee == ()
    old["reviser"]["flags"] = "rate"
    with pytest.raises(InvalidConfig, match="removed"):
        ShieldConfig.from_stored(old)


def test_a_configuration_carries_its_version_and_refuses_another() -> None:
    data = ShieldConfig().to_dict()
    assert data["version"] == 5 and ShieldConfig.from_dict(data) == ShieldConfig()
    with pytest.raises(InvalidConfig) as raised:
        ShieldConfig.from_dict({**data, "version": 4})
    assert raised.value.field == "version"


def test_a_version_2_configuration_of_the_local_risk_model_loads_as_it_was() -> None:
    config = ShieldConfig.from_dict({"risk": {"horizon": 12, "margin": 0.01}})
    without_reach = dataclasses.replace(config, risk=RiskConfig(12, margin=0.01, reach_horizon=0))
    assert ShieldConfig.from_stored(version_2(config.to_dict())) == without_reach
    paper = version_2(ShieldConfig.paper().to_dict())
    paper["risk"]["model"] = "counts"  # not read by the paper's reviser
    assert ShieldConfig.from_stored(paper) == ShieldConfig.paper()


@pytest.mark.parametrize("model", ["counts", None])
def test_a_stored_risk_reviser_of_the_counted_model_is_refused_by_name(model: str | None) -> None:
    """The counted risk model was removed in version 3; a version-2 configuration without
    ``risk.model`` was written before the local model existed, so it used the counted one."""
    old = version_2(ShieldConfig().to_dict())
    if model is None:
        del old["risk"]["model"]
    else:
        old["risk"]["model"] = model
    with pytest.raises(InvalidConfig, match="removed in configuration version 3") as raised:
        ShieldConfig.from_stored(old)
    assert raised.value.field == "risk.model"
    snapshot = Shield().snapshot()
    snapshot["config"] = old
    with pytest.raises(InvalidSnapshot) as refused:
        Shield.from_snapshot(snapshot)
    assert refused.value.field == "config.risk.model"


def test_a_damaged_snapshot_is_refused() -> None:
    data = Shield().snapshot()
    with pytest.raises(InvalidSnapshot):
        Shield.from_snapshot({**data, "format": 99})
    with pytest.raises(InvalidSnapshot):
        Shield.from_snapshot({k: v for k, v in data.items() if k != "clustering"})


def test_dense_and_lazy_backends_decide_alike() -> None:
    lazy = Shield(cliff_config())
    dense = Shield(dataclasses.replace(cliff_config(), limits=LimitsConfig(tpm_backend="dense")))
    _, pairs_lazy = run_cliff(lazy, 50, seed=8)
    _, pairs_dense = run_cliff(dense, 50, seed=8)
    assert np.array(pairs_lazy) == pytest.approx(np.array(pairs_dense))
    for a in range(20):
        assert lazy.transitions.matrix(a) == pytest.approx(dense.transitions.matrix(a), abs=1e-12)


def test_max_states_bounds_the_model() -> None:
    shield = Shield(ShieldConfig(limits=LimitsConfig(max_states=4)))
    for z, a, done in random_stream(1, 300):
        shield.step(z, a, done=done)
    assert shield.n_states == 4 and shield.clusterer.capacity_hits > 0


def test_states_view_reports_physical_centres() -> None:
    shield = Shield()
    shield.step([16.0, 100.0, 8.0], 0.0)
    states = shield.states()
    assert states["centre"][0] == pytest.approx([16.0, 100.0, 8.0])
    assert states["flag"] == [None] and states["visits"].tolist() == [1]


def test_a_knee_keeps_the_views_in_physical_units() -> None:
    shield = Shield(ShieldConfig.from_dict({"observation": {"knee": [0.0, 20.0, 0.0]}}))
    shield.step([16.0, 100.0, 8.0], 0.0)
    assert shield.states()["centre"][0] == pytest.approx([16.0, 100.0, 8.0])
    assert shield.state_view(0)["centre"] == pytest.approx([16.0, 100.0, 8.0])


@pytest.mark.parametrize(
    ("knee", "field"),
    [
        ([20.0], "observation.knee"),
        ([0.0, -1.0, 0.0], "observation.knee"),
        ([0.0, math.inf, 0.0], "observation.knee.1"),
    ],
)
def test_a_bad_knee_names_its_field(knee: list[float], field: str) -> None:
    with pytest.raises(ShieldError) as raised:
        ShieldConfig.from_dict({"observation": {"knee": knee}})
    assert raised.value.field == field


def test_an_empty_model_has_empty_views_and_snapshots() -> None:
    shield = Shield()
    assert shield.transitions.matrix(0).shape == (0, 0)
    assert shield.states()["centre"].shape == (0, 3)
    assert_same(Shield.from_snapshot(shield.snapshot()).snapshot(), shield.snapshot())
    what_if = shield.step([1.0, 2.0, 3.0], 0.5, learn=False)
    assert what_if.reason == "cold_start" and shield.n_states == 0


def test_a_model_that_saw_one_point_twice_restores() -> None:
    """The potential's recursion rounds a repeated point to 1 + 2^-52, just above its bound
    of 1: the model's own snapshot must still restore."""
    shield = Shield(ShieldConfig())
    for _ in range(2):
        shield.step([10.0, 12.0, 9.0], 0.5, stream="s")
    assert max(shield.snapshot()["clustering"]["potentials"]) > 1.0
    restored = Shield.from_snapshot(shield.snapshot())
    assert restored.step([11.0, 12.0, 9.0], 0.5, stream="s") == shield.step(
        [11.0, 12.0, 9.0], 0.5, stream="s"
    )
