"""Held-out world for #68 (a runaway and an extinction on either side of an unstable operating
point): a chain-reacting pile with a positive temperature coefficient, held at the power asked
by its control rods.

The pile's power follows the reactivity: above critical it grows, below it dies away, and a
change of the rods jumps the power at once (the prompt jump) before the delayed neutrons carry
it on. Its fuel warms with the power (5 s behind it) and, as in some graphite piles, warmer
fuel adds reactivity: a little more power makes it hotter and so more reactive, a little less
makes it cooler and less reactive. Every operating point is unstable: left alone at rated
power, the pile runs away or dies away within 0.5-2 minutes. The coolant's inlet temperature
wanders and adds its own reactivity through the fuel. The action is the rods' reactivity, in
[-0.3, 0.3] dollars. Failures: ``runaway``, the power above 1.5 of rated (fought by less
reactivity), and ``extinction``, the power below 0.3 (the chain reaction dying away; fought
by more).

Point kinetics with one group of delayed neutrons and the prompt jump, in dollars:
power n = c / (1 - rho); precursors dc/dt = lambda (n - c); fuel dT/dt = (T_c + R n - T) / tau;
reactivity rho = rods + alpha (T - T_0), where T_0 is the fuel's temperature at rated power
and the design inlet temperature.

The controller is the pile's power regulator: rods set in proportion to the gap between the
power asked and the power read, plus the integral of that gap, on an ionisation chamber that
lags 4 s behind the power. Its gains are drawn per episode (a regulator tuned now well, now
too loose to catch the drift), and the power asked changes every 30-90 s between 0.5 and 1.25
of rated, so that it overshoots and lags. Time step 0.5 s; at most 300 steps (150 s), ending
at the first failure. The shield observes ``[power, fuel temperature, inlet temperature, power
asked]``: fractions of rated power and degC. The controller's task figure (``info["task"]``,
per step) is the absolute gap between the power and the power asked, in fractions of rated
power. Held out: not used to choose any default (bench/heldout/README.md).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium.spaces import Box

from app.core import Bound, ShieldConfig
from bench.worlds.harness import Spaces, World
from client.shield.spaces import config_for

DT = 0.5  # [s]
SUBSTEPS = 5  # Euler steps of the physics per step
MAX_STEPS = 300  # 150 s
DECAY = 0.1  # [1/s] lambda, the delayed neutrons' precursors
TAU_FUEL = 5.0  # [s]
RISE = 40.0  # [K] the fuel's rise over the inlet at rated power
INLET = 280.0  # [degC] the design inlet temperature
ALPHA = 0.008  # [$/K] the fuel's temperature coefficient, positive
RODS_MAX = 0.3  # [$]
RUNAWAY = 1.5  # [rated]
EXTINCTION = 0.3  # [rated]
ASKED = (0.5, 1.25)  # [rated] the range of the power asked
CHAMBER_LAG = 4.0  # [s] the ionisation chamber


class Pile:
    """The environment: reset/step like Gymnasium, with ``info["event"]`` and
    ``info["task"]``."""

    def __init__(self) -> None:
        self.rng = np.random.default_rng(0)
        self.power = self.precursors = self.fuel = self.inlet = self.asked = 0.0
        self.asked_left = 0

    def reset(self, seed: int | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        self.rng = np.random.default_rng(seed)
        self.asked = float(self.rng.uniform(0.7, 1.1))
        self.asked_left = int(self.rng.integers(60, 181))
        self.power = self.precursors = self.asked
        self.inlet = INLET + float(self.rng.normal(0.0, 2.0))
        self.fuel = self.inlet + RISE * self.power
        return self._obs(), {"event": None, "task": 0.0}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        rods = min(max(float(np.asarray(action).reshape(-1)[0]), -RODS_MAX), RODS_MAX)
        h = DT / SUBSTEPS
        for _ in range(SUBSTEPS):
            rho = rods + ALPHA * (self.fuel - INLET - RISE)  # [$]
            self.power = self.precursors / (1.0 - rho)  # n = c / (1 - rho), the prompt jump
            self.precursors += DECAY * (self.power - self.precursors) * h
            self.fuel += (self.inlet + RISE * self.power - self.fuel) / TAU_FUEL * h
        # the inlet wanders about its design temperature
        self.inlet += 0.02 * (INLET - self.inlet) * DT + 0.6 * float(self.rng.normal())
        self.asked_left -= 1
        if self.asked_left == 0:
            self.asked = float(self.rng.uniform(*ASKED))
            self.asked_left = int(self.rng.integers(60, 181))
        event = (
            "runaway" if self.power > RUNAWAY else "extinction" if self.power < EXTINCTION else None
        )
        return (
            self._obs(),
            0.0,
            event is not None,
            False,
            {"event": event, "task": abs(self.power - self.asked)},
        )

    def _obs(self) -> np.ndarray:
        return np.array([self.power, self.fuel, self.inlet, self.asked])


class Regulator:
    """Rods ``kp e + ki integral(e)``, clipped, with e the power asked less the power read on
    a chamber that lags ``CHAMBER_LAG``; the gains are drawn per episode."""

    def __init__(self, seed: int) -> None:
        self.rng = np.random.default_rng(seed)
        self.kp = self.ki = self.integral = 0.0
        self.read: float | None = None

    def reset(self) -> None:
        self.kp = float(np.exp(self.rng.uniform(np.log(0.05), np.log(0.8))))  # [$/rated]
        self.ki = float(np.exp(self.rng.uniform(np.log(0.002), np.log(0.05))))  # [$/rated/s]
        self.integral = 0.0
        self.read = None

    def __call__(self, obs: np.ndarray) -> float:
        power, _, _, asked = (float(v) for v in obs)
        # the chamber: d read/dt = (power - read) / lag
        self.read = (
            power if self.read is None else self.read + (power - self.read) * DT / CHAMBER_LAG
        )
        gap = asked - self.read
        self.integral += gap * DT
        return min(max(self.kp * gap + self.ki * self.integral, -RODS_MAX), RODS_MAX)


# What a new user writes (client.shield.config_for): the ranges the observation usually
# takes, the rods' range in 20 bins, and each failure with the direction of reactivity that
# moves away from it; the second adds where each failure lies.
SPACES = Spaces(
    observation_space=Box(
        low=np.array([0.0, 250.0, 260.0, 0.0]),
        high=np.array([2.0, 360.0, 300.0, 1.5]),
        dtype=np.float64,
    ),
    action_space=Box(low=-RODS_MAX, high=RODS_MAX, shape=(1,), dtype=np.float64),
)
CONFIG: ShieldConfig = config_for(SPACES, {"runaway": "decrease", "extinction": "increase"})
BOUNDED: ShieldConfig = config_for(
    SPACES,
    {
        "runaway": ("decrease", Bound("x0", above=RUNAWAY)),
        "extinction": ("increase", Bound("x0", below=EXTINCTION)),
    },
)


def _world(name: str, config: ShieldConfig) -> World:
    return World(
        name=name,
        make=lambda seed: Pile(),
        controller=Regulator,
        config=config,
        event=lambda obs, info: info["event"],
        shield_observation=lambda obs: [float(v) for v in obs],
        max_steps=MAX_STEPS,
    )


WORLD = _world("pile", CONFIG)
WORLD_BOUNDED = _world("pile-bounded", BOUNDED)
