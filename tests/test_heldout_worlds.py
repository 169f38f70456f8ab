"""The held-out worlds of ``bench/heldout`` run, fail without help in the ways their
configurations name, and their physics goes the way their docstrings say. No shield is built
here: these worlds stay unseen by the shield until a candidate default is judged on them."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from bench.heldout import NAMES, bicycle, greenhouse, pile, world
from bench.worlds.harness import run


@pytest.mark.parametrize("bounded", [False, True])
@pytest.mark.parametrize("name", NAMES)
def test_a_world_fails_alone_in_every_way_its_configuration_names(name: str, bounded: bool) -> None:
    chosen = world(name, bounded)
    alone = run(chosen, seed=7, episodes=60, warmup=0, config=None)
    assert 0.1 < alone["total"] / alone["episodes"] < 0.8  # fails often, not always
    assert set(alone["failures"]) == {c.name for c in chosen.config.criteria}
    assert all((c.bound is not None) == bounded for c in chosen.config.criteria)
    assert alone["steps"] <= 60 * chosen.max_steps <= 60 * 300


def test_an_unknown_world_is_refused_with_the_names_there_are() -> None:
    with pytest.raises(ValueError, match="greenhouse, bicycle, pile"):
        world("tank")


def first_event(
    env: Any,
    seed: int,
    policy: Callable[[int, np.ndarray], float],
    setup: Callable[[Any], None] | None = None,
) -> tuple[str | None, int]:
    """The first failure of one episode under ``policy(step, observation)``, and its step."""
    observation, _ = env.reset(seed=seed)
    if setup is not None:
        setup(env)
        observation = env._obs()
    for step in range(1, 301):
        observation, _, _, _, info = env.step(np.array([policy(step, observation)]))
        if info["event"] is not None:
            return str(info["event"]), step
    return None, 300


@pytest.mark.parametrize("seed", range(6))
def test_the_greenhouse_overheats_hours_after_too_much_heat_and_chills_on_too_little(
    seed: int,
) -> None:
    event, step = first_event(greenhouse.Greenhouse(), seed, lambda _, obs: 10.0)
    assert event == "overheat" and step * greenhouse.DT >= 0.9  # [h]: the loop is slow
    assert first_event(greenhouse.Greenhouse(), seed, lambda _, obs: 0.0)[0] == "chill"


@pytest.mark.parametrize("seed", range(4))
def test_steering_into_a_lean_rights_the_bicycle_but_carries_it_to_that_side(seed: int) -> None:
    def leaning_right(env: Any) -> None:
        env.lean, env.rate, env.heading, env.offset = 0.1, 0.0, 0.0, 0.0

    untouched = first_event(bicycle.Bicycle(), seed, lambda _, obs: 0.0, leaning_right)
    assert untouched[0] == "fall_right"  # unstable: a lean grows
    env = bicycle.Bicycle()
    steered = first_event(env, seed, lambda _, obs: 0.2, leaning_right)
    assert steered[0] == "fall_left"  # steering right swings the lean over to the left
    assert env.offset > 0.0 and env.heading > 0.0  # and the bicycle went right


@pytest.mark.parametrize("seed", range(4))
def test_the_pile_runs_away_above_its_operating_point_and_dies_away_below(seed: int) -> None:
    def at(power: float) -> Callable[[Any], None]:
        def setup(env: Any) -> None:
            env.power = env.precursors = power
            env.fuel = env.inlet + pile.RISE * power

        return setup

    def held(step: int, observation: np.ndarray) -> float:
        return 0.0

    assert first_event(pile.Pile(), seed, held, at(1.2))[0] == "runaway"
    assert first_event(pile.Pile(), seed, held, at(0.8))[0] == "extinction"
    assert first_event(pile.Pile(), seed, lambda _, obs: pile.RODS_MAX)[0] == "runaway"
    assert first_event(pile.Pile(), seed, lambda _, obs: -pile.RODS_MAX)[0] == "extinction"


def test_a_world_replays_exactly_from_its_seed() -> None:
    chosen = world("bicycle")
    assert run(chosen, 3, 20, 0, None) == run(chosen, 3, 20, 0, None)
