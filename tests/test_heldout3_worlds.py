"""The third set of held-out worlds (``bench/heldout3``) run, fail without help in the ways
their configurations name, report the controller's task figure, and their physics goes the
way their docstrings say. No shield is built here: these worlds stay unseen by the shield
until a candidate default is judged on them."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from bench.heldout3 import NAMES, anaesthesia, fusion, trailer, world
from bench.worlds.__main__ import world_named
from bench.worlds.harness import run

DIRECTIONS = {
    "anaesthesia": {"hypotension": "decrease", "awareness": "increase"},
    "trailer": {
        "jackknife_left": "increase",
        "jackknife_right": "decrease",
        "kerb_left": "increase",
        "kerb_right": "decrease",
    },
    "fusion": {"runaway": "decrease", "extinction": "increase"},
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
    with pytest.raises(ValueError, match="anaesthesia, trailer, fusion"):
        world("reactor")


def test_bench_worlds_finds_the_third_set_by_its_prefix() -> None:
    assert world_named("heldout3_fusion").name == "fusion"
    assert world_named("heldout3_trailer_bounded").name == "trailer-bounded"
    with pytest.raises(SystemExit, match="third set"):
        world_named("heldout3_nowhere")


def first_event(
    env: Any,
    seed: int,
    policy: Callable[[int, np.ndarray], float],
    setup: Callable[[Any], None] | None = None,
    steps: int = 300,
) -> tuple[str | None, int]:
    """The first failure of one episode under ``policy(step, observation)``, and its step."""
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


@pytest.mark.parametrize("seed", [0, 1, 2, 3, 7, 8])  # three in four overdose in 2 h
def test_the_patient_wakes_with_no_propofol_and_its_pressure_falls_late_on_too_much(
    seed: int,
) -> None:
    assert first_event(anaesthesia.Patient(), seed, lambda _, obs: 0.0, steps=120)[0] == (
        "awareness"
    )

    def calm(env: Any) -> None:
        env.bleed = 0.0

    event, step = first_event(
        anaesthesia.Patient(), seed, lambda _, obs: anaesthesia.RATE_MAX, calm, steps=120
    )
    assert event == "hypotension" and step * anaesthesia.DT >= 8.0  # [min]: the pressure lags


def test_the_pressure_lags_the_brain() -> None:
    env = anaesthesia.Patient()
    env.reset(seed=3)
    assert env.km < env.ke0  # the pressure's effect site is the slower
    brain, pressure = [], []
    for _ in range(10):
        env.step(np.array([anaesthesia.RATE_MAX]))
        brain.append(env.ce)
        pressure.append(env.cm)
    assert brain[-1] > pressure[-1] > pressure[0]


@pytest.mark.parametrize("seed", range(4))
def test_the_trailer_jackknifes_unsteered_and_saving_it_from_a_kerb_swings_the_hitch(
    seed: int,
) -> None:
    def swung(hitch: float, offset: float = 0.0) -> Callable[[Any], None]:
        def setup(env: Any) -> None:
            env.hitch, env.knock, env.steer = hitch, 0.0, 0.0
            env.y = env.path(env.x) + offset
            env.heading = float(np.arctan(env.path_slope(env.x)))

        return setup

    event, step = first_event(trailer.Trailer(), seed, lambda _, obs: 0.0, swung(0.3))
    assert event in ("jackknife_left", "kerb_left") and step * trailer.DT <= 10.0  # [s]

    def steer_for_a_second(angle: float) -> Callable[[int, np.ndarray], float]:
        return lambda step, obs: angle if step <= 5 else 0.0

    near_left_kerb = swung(0.0, 0.9)
    assert first_event(
        trailer.Trailer(), seed, steer_for_a_second(-trailer.STEER_MAX), near_left_kerb
    )[0] == ("kerb_left")
    saved = first_event(
        trailer.Trailer(), seed, steer_for_a_second(trailer.STEER_MAX), near_left_kerb
    )
    assert saved[0] == "jackknife_right"  # the steering that left the kerb swung the hitch
    held = first_event(trailer.Trailer(), seed, lambda _, obs: trailer.STEER_MAX, swung(0.55))
    assert held[0] == "kerb_left"  # straightening the hitch carries the trailer to a kerb


@pytest.mark.parametrize("seed", range(4))
def test_the_burn_runs_away_above_its_operating_point_and_goes_out_below(seed: int) -> None:
    def at(share: float) -> Callable[[Any], None]:
        def setup(env: Any) -> None:
            env.kept = env.held()
            env.energy *= share

        return setup

    def kept(env: Any) -> Callable[[int, np.ndarray], float]:
        return lambda step, obs: float(env.kept)

    hot, cold = fusion.Plasma(), fusion.Plasma()
    assert first_event(hot, seed, kept(hot), at(1.1))[0] == "runaway"
    assert first_event(cold, seed, kept(cold), at(0.9))[0] == "extinction"
    assert first_event(fusion.Plasma(), seed, lambda _, obs: 0.0)[0] == "extinction"
    assert first_event(fusion.Plasma(), seed, lambda _, obs: fusion.HEATING_MAX)[0] == "runaway"


@pytest.mark.parametrize("name", NAMES)
def test_a_world_replays_exactly_from_its_seed(name: str) -> None:
    chosen = world(name)
    assert run(chosen, 3, 10, 0, None) == run(chosen, 3, 10, 0, None)
