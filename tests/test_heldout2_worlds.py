"""The second set of held-out worlds (``bench/heldout2``) run, fail without help in the ways
their configurations name, report the controller's task figure, and their physics goes the
way their docstrings say. No shield is built here: these worlds stay unseen by the shield
until a candidate default is judged on them."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from bench.heldout2 import NAMES, aircraft, field, reactor, world
from bench.worlds.harness import run

DIRECTIONS = {
    "field": {"waterlogged": "decrease", "wilting": "increase"},
    "aircraft": {
        "stall": "decrease",
        "negative_stall": "increase",
        "ground": "increase",
        "ceiling": "decrease",
    },
    "reactor": {"runaway": "increase", "quench": "decrease"},
}


@pytest.mark.parametrize("bounded", [False, True])
@pytest.mark.parametrize("name", NAMES)
def test_a_world_fails_alone_in_the_ways_its_configuration_names(name: str, bounded: bool) -> None:
    chosen = world(name, bounded)
    alone = run(chosen, seed=7, episodes=40, warmup=0, config=None)
    assert 0.1 < alone["total"] / alone["episodes"] < 0.8  # fails often, not always
    assert set(alone["failures"]) <= {c.name for c in chosen.config.criteria}
    assert len(alone["failures"]) >= 2  # more than one way, in 40 episodes
    assert alone["task"] is not None and alone["task"] >= 0.0  # the task figure is reported
    assert alone["steps"] <= 40 * chosen.max_steps <= 40 * 300


@pytest.mark.parametrize("name", NAMES)
def test_a_configuration_names_each_failure_with_its_direction_and_bound(name: str) -> None:
    plain, bounded = world(name), world(name, bounded=True)
    assert {c.name: c.direction for c in plain.config.criteria} == DIRECTIONS[name]
    assert {c.name: c.direction for c in bounded.config.criteria} == DIRECTIONS[name]
    assert all(c.bound is None for c in plain.config.criteria)
    assert all(c.bound is not None for c in bounded.config.criteria)
    assert plain.config.action.n_bins == bounded.config.action.n_bins == 20
    assert plain.name != bounded.name


def test_an_unknown_world_is_refused_with_the_names_there_are() -> None:
    with pytest.raises(ValueError, match="field, aircraft, reactor"):
        world("greenhouse")


def first_event(
    env: Any,
    seed: int,
    policy: Callable[[int, np.ndarray], float],
    setup: Callable[[Any], None] | None = None,
) -> tuple[str | None, int]:
    """The first failure of one episode under ``policy(step, observation)``, and its step."""
    observation, info = env.reset(seed=seed)
    assert info["event"] is None and info["task"] >= 0.0
    if setup is not None:
        setup(env)
        observation = env._obs()
    for step in range(1, 301):
        observation, _, terminated, truncated, info = env.step(
            np.array([policy(step, observation)])
        )
        assert not truncated and terminated == (info["event"] is not None)
        assert info["task"] >= 0.0
        if info["event"] is not None:
            return str(info["event"]), step
    return None, 300


@pytest.mark.parametrize("seed", range(6))
def test_the_field_waterlogs_a_day_after_too_much_water_and_wilts_on_too_little(seed: int) -> None:
    event, step = first_event(field.Field(), seed, lambda _, obs: field.VALVE_MAX)
    assert event == "waterlogged" and step * field.DT >= 12.0  # [h]: the subsoil fills first

    def dry(env: Any) -> None:
        env.root = 0.21 * field.ROOT

    assert first_event(field.Field(), seed, lambda _, obs: 0.0, dry)[0] == "wilting"


@pytest.mark.parametrize("seed", range(4))
def test_the_drone_pitches_away_when_unstable_and_pulling_up_from_the_ground_stalls_it(
    seed: int,
) -> None:
    def unstable(env: Any) -> None:
        env.stiffness = 25.0  # [1/s^2]: an aft centre of gravity

    event, step = first_event(aircraft.Aircraft(), seed, lambda _, obs: 0.0, unstable)
    assert event in ("stall", "negative_stall") and step * aircraft.DT <= 6.0  # [s]

    def sinking_low(env: Any) -> None:
        env.stiffness = 0.0  # a stable drone, sinking at 4.4 m/s 20 m above the ground
        env.height, env.path, env.rate = 20.0, -0.2, 0.0
        env.pitch = env.path + aircraft.TRIM

    held = first_event(aircraft.Aircraft(), seed, lambda _, obs: 0.0, sinking_low)
    assert held[0] == "ground"
    pulled = first_event(
        aircraft.Aircraft(), seed, lambda _, obs: aircraft.ELEVATOR_MAX, sinking_low
    )
    assert pulled[0] == "stall"  # the pull that leaves the ground behind stalls the wing


@pytest.mark.parametrize("seed", range(4))
def test_the_reactor_runs_away_above_its_operating_point_and_dies_down_below(seed: int) -> None:
    def at(temperature: float) -> Callable[[Any], None]:
        def setup(env: Any) -> None:
            env.temp = temperature
            env.conc = (
                reactor.FEED_FLOW
                * env.feed_conc
                / (reactor.FEED_FLOW + reactor.VOLUME * reactor.rate(350.0))
            )
            env.jacket = reactor.JACKET_HELD

        return setup

    def held(step: int, observation: np.ndarray) -> float:
        return reactor.HELD

    assert first_event(reactor.Reactor(), seed, held, at(352.0))[0] == "runaway"
    assert first_event(reactor.Reactor(), seed, held, at(348.0))[0] == "quench"
    assert first_event(reactor.Reactor(), seed, lambda _, obs: 0.0)[0] == "runaway"
    assert first_event(reactor.Reactor(), seed, lambda _, obs: reactor.FLOW_MAX)[0] == "quench"


@pytest.mark.parametrize("name", NAMES)
def test_a_world_replays_exactly_from_its_seed(name: str) -> None:
    chosen = world(name)
    assert run(chosen, 3, 10, 0, None) == run(chosen, 3, 10, 0, None)
