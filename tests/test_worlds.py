"""The held-out worlds of ``bench/worlds`` run, fail without help, and take a shield."""

from __future__ import annotations

import dataclasses
import importlib
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from bench.worlds.__main__ import world_named
from bench.worlds.harness import compare, controller_seed, run, summary_line

WORLDS = ["braking_lead", "pendulum", "wall", "lane"]


@pytest.mark.parametrize("name", WORLDS)
def test_a_world_fails_without_the_shield_and_runs_with_it(name: str) -> None:
    world = importlib.import_module(f"bench.worlds.{name}").WORLD
    alone = run(world, seed=7, episodes=12, warmup=2, config=None)
    assert alone["total"] > 0  # a held-out world is one the controller fails in
    assert set(alone["failures"]) <= {c.name for c in world.config.criteria}
    shielded = run(world, seed=7, episodes=12, warmup=2, config=world.config)
    assert shielded["states"] > 0 and shielded["episodes"] == 10


def test_the_lane_is_left_on_the_side_the_bend_pushes_towards_and_steering_turns_it() -> None:
    from bench.worlds.lane import A_MAX, Lane

    def first_event(push: float, action: float) -> str | None:
        env = Lane()
        env.reset(seed=5)
        env.push, env.bend_left = push, 10_000  # one long bend
        for _ in range(300):
            *_, info = env.step(np.array([action]))
            if info["event"]:
                return str(info["event"])
        return None

    assert first_event(1.0, 0.0) == "departure_left"
    assert first_event(-1.0, 0.0) == "departure_right"
    assert first_event(1.0, -A_MAX) == "departure_right"  # steering beats the bend
    assert first_event(-1.0, A_MAX) == "departure_left"


def test_compare_is_deterministic() -> None:
    world = importlib.import_module("bench.worlds.wall").WORLD
    first = compare(world, [3], episodes=8, warmup=2)
    assert first == compare(world, [3], episodes=8, warmup=2)
    assert first["alone"] == sum(first["runs"][0]["alone"]["failures"].values())


def test_each_episode_builds_its_controller_from_the_seed_and_the_episode_alone() -> None:
    # common random numbers: an episode's controller does not depend on the episodes before
    # it, so an episode the shield leaves alone is the controller's own episode
    base = world_named("heldout_bicycle")
    built: list[int] = []

    def controller(seed: int) -> Any:
        built.append(seed)
        return base.controller(seed)

    world = dataclasses.replace(base, controller=controller)
    run(world, seed=3, episodes=4, warmup=0, config=None)
    run(world, seed=3, episodes=4, warmup=0, config=world.config)
    assert built == [controller_seed(3, episode) for episode in range(4)] * 2
    assert len(set(built)) == 4 and controller_seed(4, 0) not in built


@pytest.mark.parametrize("name", ["tuning_sluggish", "tuning_collapsed_plain"])
def test_the_slow_failure_tuning_worlds_fall_behind_without_the_shield(name: str) -> None:
    alone = run(world_named(name), seed=0, episodes=6, warmup=0, config=None)
    assert set(alone["failures"]) == {"large_distance"} and alone["total"] >= 3


def test_the_flat_out_tuning_world_collides_without_the_shield_and_the_shield_drives() -> None:
    world = world_named("tuning_flat_out")
    alone = run(world, seed=0, episodes=6, warmup=0, config=None)
    assert set(alone["failures"]) == {"collision"} and alone["total"] >= 5
    shielded = run(world, seed=0, episodes=6, warmup=0, config=world.config)
    assert shielded["revised"] > shielded["steps"] / 2  # every proposal is full acceleration


def test_the_plain_tuning_worlds_differ_only_in_the_configuration() -> None:
    default, plain = world_named("tuning_idm"), world_named("tuning_idm_plain")
    assert plain.config.observation.high == (35.0, 200.0, 35.0)
    assert plain.config.observation.knee == ()
    assert plain.config.to_dict()["risk"] == default.config.to_dict()["risk"]


def test_the_tank_fails_both_ways_alone_and_the_shield_learns_from_it() -> None:
    # (seed 1: on seed 0 the record's pooled comparison backs off everywhere early, and the
    # shield stands back for the whole run, as it did before the trial)
    world = world_named("tuning_tank")
    alone = run(world, seed=1, episodes=30, warmup=0, config=None)
    assert set(alone["failures"]) == {"overflow", "dry"}
    shielded = run(world, seed=1, episodes=30, warmup=0, config=world.config)
    assert shielded["total"] < alone["total"] and shielded["states"] >= 2


@pytest.mark.parametrize("seed", [0, 3])
def test_the_lander_always_lands_hard_alone_and_the_shield_learns_to_fire_earlier(
    seed: int,
) -> None:
    # its failure builds up over more steps than the horizon, from a controller that fires
    # only too late: the shield must try firing harder where the controller never did (seed
    # 0, with 3-4 broad states, needs the reach: the local model alone reads every thrust alike)
    world = world_named("tuning_lander")
    alone = run(world, seed=seed, episodes=40, warmup=20, config=None)
    assert alone["failures"] == {"hard_landing": 20}
    shielded = run(world, seed=seed, episodes=40, warmup=20, config=world.config)
    assert shielded["total"] <= 2


def test_an_unknown_world_is_refused_with_the_names_there_are() -> None:
    with pytest.raises(SystemExit, match="tuning_tank"):
        world_named("tuning_nowhere")
    with pytest.raises(SystemExit, match="braking_lead"):
        world_named("nowhere")


def test_a_run_counts_the_warm_up_apart_and_what_the_shield_took_over() -> None:
    world = importlib.import_module("bench.worlds.braking_lead").WORLD
    whole = run(world, seed=7, episodes=12, warmup=0, config=None)
    split = run(world, seed=7, episodes=12, warmup=5, config=None)
    assert split["early_total"] + split["total"] == whole["total"] > 0
    assert split["revised"] == 0 and split["revised_share"] == 0.0 and split["task"] is None
    shielded = run(world, seed=7, episodes=12, warmup=2, config=world.config)
    assert 0 < shielded["revised"] <= shielded["steps"]
    assert shielded["revised_share"] == shielded["revised"] / shielded["steps"]
    assert shielded["mean_revision"] > 0.0


def test_compare_names_the_worst_seed_and_the_seeds_a_shield_harmed() -> None:
    world = importlib.import_module("bench.worlds.braking_lead").WORLD
    result = compare(world, [7, 8], episodes=8, warmup=2)
    ratios = [r["ratio"] for r in result["runs"]]
    assert result["worst_seed_ratio"] == max(r for r in ratios if r is not None)
    assert result["harmed_seeds"] == [
        r["seed"] for r in result["runs"] if r["shielded"]["total"] > r["alone"]["total"]
    ]
    assert "worst seed" in summary_line(result) and "revised" in summary_line(result)


def test_a_world_that_reports_a_task_figure_has_it_averaged_per_step() -> None:
    from bench.heldout import world as heldout  # alone only: these worlds are held out

    result = run(heldout("pile"), seed=2000, episodes=2, warmup=0, config=None)
    assert result["task"] is not None and result["task"] >= 0.0


def test_the_table_gives_each_worlds_figures_in_a_row(tmp_path: Path) -> None:
    import json

    from bench.worlds.table import table

    world = importlib.import_module("bench.worlds.braking_lead").WORLD
    result = compare(world, [7], episodes=6, warmup=2)
    path = tmp_path / "one.json"
    path.write_text(json.dumps({"results": [result]}))
    header, rule, line = table([path]).splitlines()
    cells = [c.strip() for c in line.strip("|").split("|")]
    assert len(cells) == header.count("|") - 1 == rule.count("|") - 1
    assert cells[:3] == [world.name, str(result["alone"]), str(result["shielded"])]
    revised = result["runs"][0]["shielded"]["revised_share"]
    assert cells[8] == f"{revised:.1%}" and cells[10] == "-"  # this world reports no task


def test_the_held_out_worlds_of_68_are_found_by_name_with_or_without_bounds() -> None:
    assert world_named("heldout_pile").name == "pile"
    assert world_named("heldout_pile_bounded").name == "pile-bounded"
    assert world_named("heldout2_reactor").name == "reactor"  # the second set
    assert world_named("heldout2_aircraft_bounded").name == "aircraft-bounded"
    with pytest.raises(SystemExit, match="no held-out world 'nowhere'"):
        world_named("heldout_nowhere")
