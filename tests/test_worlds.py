"""The held-out worlds of ``bench/worlds`` run, fail without help, and take a shield."""

from __future__ import annotations

import importlib

import pytest

from bench.worlds.harness import compare, run

WORLDS = ["braking_lead", "pendulum", "wall"]


@pytest.mark.parametrize("name", WORLDS)
def test_a_world_fails_without_the_shield_and_runs_with_it(name: str) -> None:
    world = importlib.import_module(f"bench.worlds.{name}").WORLD
    alone = run(world, seed=7, episodes=12, warmup=2, config=None)
    assert alone["total"] > 0  # a held-out world is one the controller fails in
    assert set(alone["failures"]) <= {c.name for c in world.config.criteria}
    shielded = run(world, seed=7, episodes=12, warmup=2, config=world.config)
    assert shielded["states"] > 0 and shielded["episodes"] == 10


def test_compare_is_deterministic() -> None:
    world = importlib.import_module("bench.worlds.wall").WORLD
    first = compare(world, [3], episodes=8, warmup=2)
    assert first == compare(world, [3], episodes=8, warmup=2)
    assert first["alone"] == sum(first["runs"][0]["alone"]["failures"].values())


@pytest.mark.parametrize("name", ["SLUGGISH_WORLD", "COLLAPSED_WORLD"])
def test_the_slow_failure_tuning_worlds_fall_behind_without_the_shield(name: str) -> None:
    world = getattr(importlib.import_module("bench.worlds.tuning"), name)
    alone = run(world, seed=0, episodes=6, warmup=0, config=None)
    assert set(alone["failures"]) == {"large_distance"} and alone["total"] >= 3
