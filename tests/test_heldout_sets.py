"""What every set of held-out worlds of #68 (``bench/heldout2`` to ``bench/heldout4``) must be: its
worlds fail without help in the ways their configurations name, report the controller's task
figure, replay from their seeds, and are found by ``python -m bench.worlds``. No shield is built
here: these worlds stay unseen by the shield until a candidate default is judged on them. Each
set's physics is tested in its own module (``test_heldout2_worlds.py`` and the others)."""

from __future__ import annotations

from collections.abc import Callable
from types import ModuleType
from typing import Any

import numpy as np
import pytest

import bench.heldout2
import bench.heldout3
import bench.heldout4
from bench.worlds.__main__ import world_named
from bench.worlds.harness import run

# per set: each world's failures and their declared safe directions
DIRECTIONS: dict[ModuleType, dict[str, dict[str, str]]] = {
    bench.heldout2: {
        "field": {"waterlogged": "decrease", "wilting": "increase"},
        "aircraft": {
            "stall": "decrease",
            "negative_stall": "increase",
            "ground": "increase",
            "ceiling": "decrease",
        },
        "reactor": {"runaway": "increase", "quench": "decrease"},
    },
    bench.heldout3: {
        "anaesthesia": {"hypotension": "decrease", "awareness": "increase"},
        "trailer": {
            "jackknife_left": "increase",
            "jackknife_right": "decrease",
            "kerb_left": "increase",
            "kerb_right": "decrease",
        },
        "fusion": {"runaway": "decrease", "extinction": "increase"},
    },
    bench.heldout4: {
        "furnace": {"chill": "increase", "overheat": "decrease"},
        "monorail": {
            "tip_left": "increase",
            "tip_right": "decrease",
            "gimbal_fore": "decrease",
            "gimbal_aft": "increase",
        },
        "arc": {"runaway": "decrease", "extinction": "increase"},
    },
}
WORLDS = [(held, name) for held, names in DIRECTIONS.items() for name in names]


def ids(value: Any) -> str:
    return value.__name__.rsplit(".", 1)[-1] if isinstance(value, ModuleType) else str(value)


@pytest.mark.parametrize("bounded", [False, True])
@pytest.mark.parametrize(("held", "name"), WORLDS, ids=ids)
def test_a_world_fails_alone_in_the_ways_its_configuration_names(
    held: ModuleType, name: str, bounded: bool
) -> None:
    chosen = held.world(name, bounded)
    alone = run(chosen, seed=7, episodes=40, warmup=0, config=None)
    assert 0.1 < alone["total"] / alone["episodes"] < 0.8  # fails often, not always
    assert set(alone["failures"]) <= {c.name for c in chosen.config.criteria}
    assert len(alone["failures"]) >= 2  # more than one way, in 40 episodes
    assert alone["task"] is not None and alone["task"] >= 0.0  # the task figure is reported
    assert alone["steps"] <= 40 * chosen.max_steps <= 40 * 300


@pytest.mark.parametrize(("held", "name"), WORLDS, ids=ids)
def test_a_configuration_names_each_failure_with_its_direction_and_bound(
    held: ModuleType, name: str
) -> None:
    plain, bounded = held.world(name), held.world(name, bounded=True)
    assert {c.name: c.direction for c in plain.config.criteria} == DIRECTIONS[held][name]
    assert {c.name: c.direction for c in bounded.config.criteria} == DIRECTIONS[held][name]
    assert all(c.bound is None for c in plain.config.criteria)
    assert all(c.bound is not None for c in bounded.config.criteria)
    assert plain.config.action.n_bins == bounded.config.action.n_bins == 20
    assert plain.name != bounded.name


@pytest.mark.parametrize(("held", "name"), WORLDS, ids=ids)
def test_a_world_replays_exactly_from_its_seed(held: ModuleType, name: str) -> None:
    chosen = held.world(name)
    assert run(chosen, 3, 10, 0, None) == run(chosen, 3, 10, 0, None)


@pytest.mark.parametrize("held", list(DIRECTIONS), ids=ids)
def test_an_unknown_world_is_refused_with_the_names_there_are(held: ModuleType) -> None:
    with pytest.raises(ValueError, match=", ".join(held.NAMES)):
        held.world("nowhere")


def test_bench_worlds_finds_each_set_by_its_prefix() -> None:
    assert world_named("heldout2_reactor").name == "reactor"
    assert world_named("heldout3_fusion").name == "fusion"
    assert world_named("heldout3_trailer_bounded").name == "trailer-bounded"
    assert world_named("heldout4_monorail_bounded").name == "monorail-bounded"
    with pytest.raises(SystemExit, match="in bench.heldout3; there are anaesthesia"):
        world_named("heldout3_nowhere")


def first_event(
    env: Any,
    seed: int,
    policy: Callable[[int, np.ndarray], float],
    setup: Callable[[Any], None] | None = None,
    steps: int = 300,
) -> tuple[str | None, int]:
    """The first failure of one episode of a held-out world's environment under
    ``policy(step, observation)``, and its step (``setup`` changes the environment after its
    reset)."""
    observation, info = env.reset(seed=seed)
    assert info["event"] is None and info["task"] >= 0.0
    if setup is not None:
        setup(env)
        observation = env._obs()
    for step in range(1, steps + 1):
        observation, _, terminated, truncated, info = env.step(
            np.array([policy(step, observation)])
        )
        assert not truncated and terminated == (info["event"] is not None)
        assert info["task"] >= 0.0
        if info["event"] is not None:
            return str(info["event"]), step
    return None, steps
