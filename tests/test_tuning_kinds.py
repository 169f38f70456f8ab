"""The three tuning worlds of the kinds issue #68 names (bench/worlds/dose.py, cartpole.py,
chemostat.py) run as their docstrings say: each is deterministic for a seed, clips its action
to the declared range, reports the task figure, can fail in every way its configuration
names (and from the side the configuration's direction says), and fails alone often but not
always. No shield is built here: these tests are about the worlds, not the shield."""

from __future__ import annotations

from collections.abc import Callable
from types import ModuleType
from typing import Any

import numpy as np
import pytest

from bench.worlds import cartpole, chemostat, dose
from bench.worlds.harness import World, run

MODULES: dict[str, ModuleType] = {"dose": dose, "cartpole": cartpole, "chemostat": chemostat}

# each failure, the direction of the action away from it, and the observation bound it has
EXPECTED: dict[str, dict[str, tuple[str, str, float | None, float | None]]] = {
    "dose": {
        "low": ("decrease", "x0", dose.LOW, None),
        "high": ("increase", "x0", None, dose.HIGH),
    },
    "cartpole": {
        "fall_right": ("increase", "x2", None, cartpole.FALL),
        "fall_left": ("decrease", "x2", -cartpole.FALL, None),
        "off_right": ("decrease", "x0", None, cartpole.EDGE),
        "off_left": ("increase", "x0", -cartpole.EDGE, None),
    },
    "chemostat": {
        "bloom": ("increase", "x0", None, chemostat.BLOOM),
        "washout": ("decrease", "x0", chemostat.WASHOUT, None),
    },
}

# the two kinds of failure each world has (a kind may have a side each)
KINDS: dict[str, tuple[set[str], set[str]]] = {
    "dose": ({"low"}, {"high"}),
    "cartpole": ({"fall_right", "fall_left"}, {"off_right", "off_left"}),
    "chemostat": ({"bloom"}, {"washout"}),
}


def episode(
    env: Any, seed: int, policy: Callable[[np.ndarray], float], steps: int
) -> tuple[list[np.ndarray], list[dict[str, Any]]]:
    """One episode of ``env`` from ``seed`` under ``policy``: the observations and infos, up
    to the first failure."""
    observation, info = env.reset(seed=seed)
    observations, infos = [observation], [info]
    for _ in range(steps):
        observation, _, terminated, truncated, info = env.step(np.array([policy(observation)]))
        observations.append(observation)
        infos.append(info)
        if terminated or truncated:
            break
    return observations, infos


def first_event(module: ModuleType, seed: int, policy: Callable[[np.ndarray], float]) -> str | None:
    """The failure that ends one episode of ``module``'s world under ``policy``."""
    world: World = module.WORLD
    _, infos = episode(world.make(seed), seed, policy, world.max_steps)
    event: str | None = infos[-1]["event"]
    return event


@pytest.mark.parametrize("name", MODULES)
def test_an_episode_is_the_same_for_the_same_seed_and_differs_for_another(name: str) -> None:
    world: World = MODULES[name].WORLD

    def trace(seed: int) -> np.ndarray:
        controller: Any = world.controller(seed)  # a controller with memory: reset
        controller.reset()
        observations, _ = episode(world.make(seed), seed, controller, 120)
        return np.array(observations)

    first, again, other = trace(3), trace(3), trace(4)
    assert first.shape == again.shape and np.array_equal(first, again)
    assert first.shape != other.shape or not np.array_equal(first, other)


@pytest.mark.parametrize("name", MODULES)
def test_an_action_beyond_the_declared_range_acts_as_its_end(name: str) -> None:
    module = MODULES[name]
    space = module.SPACES.action_space
    low, high = float(space.low[0]), float(space.high[0])
    assert (module.CONFIG.action.low, module.CONFIG.action.high) == (low, high)

    def constant(value: float) -> Callable[[np.ndarray], float]:
        return lambda observation: value

    for beyond, end in ((high + 100.0, high), (low - 100.0, low)):
        clipped, _ = episode(module.WORLD.make(0), 5, constant(beyond), 20)
        at_end, _ = episode(module.WORLD.make(0), 5, constant(end), 20)
        assert np.array_equal(np.array(clipped), np.array(at_end))


@pytest.mark.parametrize("name", MODULES)
def test_the_task_figure_is_reported_at_every_step(name: str) -> None:
    world: World = MODULES[name].WORLD
    controller: Any = world.controller(0)
    controller.reset()
    observations, infos = episode(world.make(0), 0, controller, world.max_steps)
    assert all(isinstance(info["task"], float) and info["task"] >= 0.0 for info in infos)
    assert all(len(world.shield_observation(o)) == len(observations[0]) for o in observations)


@pytest.mark.parametrize("name", MODULES)
def test_the_configuration_names_each_failure_with_its_direction_and_bound(name: str) -> None:
    module = MODULES[name]
    expected = EXPECTED[name]
    plain = {c.name: (c.direction, c.bound) for c in module.WORLD.config.criteria}
    bounded = {c.name: (c.direction, c.bound) for c in module.WORLD_BOUNDED.config.criteria}
    assert set(plain) == set(bounded) == set(expected)
    for failure, (direction, observed, below, above) in expected.items():
        assert plain[failure] == (direction, None)
        assert bounded[failure][0] == direction
        bound = bounded[failure][1]
        assert bound is not None
        assert (bound.observation, bound.below, bound.above) == (observed, below, above)
    assert module.WORLD.name == f"tuning-{name}"
    assert module.WORLD_BOUNDED.name == f"tuning-{name}-bounded"


def test_the_tuning_registry_and_the_command_line_find_the_six_worlds() -> None:
    from bench.worlds.__main__ import world_named
    from bench.worlds.tuning import WORLDS

    for name, module in MODULES.items():
        assert WORLDS[f"tuning_{name}"] is module.WORLD
        assert WORLDS[f"tuning_{name}_bounded"] is module.WORLD_BOUNDED
        assert world_named(f"tuning_{name}_bounded") is module.WORLD_BOUNDED


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_extreme_doses_end_low_and_high(seed: int) -> None:
    assert first_event(dose, seed, lambda observation: dose.RATE_MAX) == "low"
    assert first_event(dose, seed, lambda observation: 0.0) == "high"


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_extreme_dilutions_end_in_a_bloom_and_a_washout(seed: int) -> None:
    assert first_event(chemostat, seed, lambda observation: 0.0) == "bloom"
    assert first_event(chemostat, seed, lambda observation: chemostat.DILUTION_MAX) == "washout"


def balancing_towards(target: float) -> Callable[[np.ndarray], float]:
    """The design's state feedback, with no delay and no tilt, sent to ``target``."""
    k_a, k_w, k_x, k_v = cartpole.DESIGN

    def policy(observation: np.ndarray) -> float:
        x, v, theta, omega, _ = (float(value) for value in observation)
        error = min(max(x - target, -cartpole.REACH), cartpole.REACH)
        force = k_a * theta + k_w * omega + k_x * error + k_v * v
        return min(max(force, -cartpole.FORCE_MAX), cartpole.FORCE_MAX)

    return policy


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_cart_pushed_one_way_drops_the_pole_the_other_and_one_saved_runs_off(seed: int) -> None:
    # a constant push right leaves the pole behind, to the left, and a push left to the right
    assert first_event(cartpole, seed, lambda observation: cartpole.FORCE_MAX) == "fall_left"
    assert first_event(cartpole, seed, lambda observation: -cartpole.FORCE_MAX) == "fall_right"
    # the design's feedback keeps the pole up, and carries the cart off the end it is sent to
    assert first_event(cartpole, seed, balancing_towards(2.0)) == "off_right"
    assert first_event(cartpole, seed, balancing_towards(-2.0)) == "off_left"
    assert first_event(cartpole, seed, balancing_towards(0.0)) is None


@pytest.mark.parametrize("name", MODULES)
def test_the_controller_alone_fails_often_in_both_kinds(name: str) -> None:
    world: World = MODULES[name].WORLD
    alone = run(world, seed=11, episodes=80, warmup=0, config=None)
    assert 0.2 < alone["total"] / alone["episodes"] < 0.65
    first, second = KINDS[name]
    failures: dict[str, int] = alone["failures"]
    assert set(failures) <= first | second
    assert sum(failures.get(k, 0) for k in first) >= 0.15 * alone["total"]
    assert sum(failures.get(k, 0) for k in second) >= 0.15 * alone["total"]
    assert alone["task"] is not None and alone["steps"] <= 80 * world.max_steps
