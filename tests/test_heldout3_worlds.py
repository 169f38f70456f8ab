"""The physics of the third set of held-out worlds (``bench/heldout3``) goes the way their
docstrings say (what every set must be: ``test_heldout_sets.py``). No shield is built here."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from bench.heldout3 import anaesthesia, fusion, trailer
from tests.test_heldout_sets import first_event


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
