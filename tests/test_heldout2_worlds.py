"""The physics of the second set of held-out worlds (``bench/heldout2``) goes the way their
docstrings say (what every set must be: ``test_heldout_sets.py``). No shield is built here."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from bench.heldout2 import aircraft, field, reactor
from tests.test_heldout_sets import first_event


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
