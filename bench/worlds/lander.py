"""Tuning world: a lander coming down on its engine, whose failure builds up over seconds,
longer than the shield's horizon in steps (never a held-out world).

A craft starts 80-150 m up, falling at 8-15 m/s. Its controller holds the descent rate, then
fires to decelerate at 4 m/s^2 from the altitude it believes it needs, but its altimeter reads
5-30 m high (drawn per episode), so it mostly fires too late; the engine answers its command
with a lag of 0.3 s and can decelerate the craft at up to 10 m/s^2. Failures:
``hard_landing`` (touching down faster than 2 m/s) and ``climb`` (rising faster than 0.5 m/s
more than 5 m up: fuel wasted, a landing given up). Time step 0.05 s; thrust in [0, 20]
m/s^2; the shield observes ``[altitude, descent rate]``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from app.core import ActionSpec, Criterion, ObservationSpec, ShieldConfig
from bench.worlds.harness import World

DT = 0.05  # [s]
GRAVITY = 9.81  # [m/s^2]
LAG = 0.3  # [s] the engine's time constant
THRUST_MAX = 20.0  # [m/s^2]
DECELERATION = 4.0  # [m/s^2] what the controller plans to brake at


class Lander:
    """The environment: reset/step like Gymnasium, with ``info["event"]``."""

    def __init__(self) -> None:
        self.altitude = self.descent = self.thrust = 0.0

    def reset(self, seed: int | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        rng = np.random.default_rng(seed)
        self.altitude = float(rng.uniform(80.0, 150.0))
        self.descent = float(rng.uniform(8.0, 15.0))
        self.thrust = GRAVITY
        return self._obs(), {"event": None}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        command = float(np.clip(np.asarray(action).reshape(-1)[0], 0.0, THRUST_MAX))
        self.thrust += (command - self.thrust) * DT / LAG
        self.descent += (GRAVITY - self.thrust) * DT
        self.altitude -= self.descent * DT
        event = None
        landed = self.altitude <= 0.0
        if landed and self.descent > 2.0:
            event = "hard_landing"
        elif not landed and self.descent < -0.5 and self.altitude > 5.0:
            event = "climb"
        self.altitude = max(self.altitude, 0.0)
        return self._obs(), 0.0, landed or event is not None, False, {"event": event}

    def _obs(self) -> np.ndarray:
        return np.array([self.altitude, self.descent])


class LateFiring:
    """Holds its descent rate, then asks for the thrust that brakes at ``DECELERATION`` once
    the altitude it reads (too high by the episode's bias) is what that braking needs; below
    1.5 m/s it settles down gently."""

    def __init__(self, seed: int) -> None:
        self.rng = np.random.default_rng(seed)
        self.bias = 15.0
        self.firing = False

    def reset(self) -> None:
        self.bias = float(self.rng.uniform(5.0, 30.0))
        self.firing = False

    def __call__(self, obs: np.ndarray) -> float:
        altitude, descent = obs
        needed = max(descent, 0.0) ** 2 / (2.0 * DECELERATION) + 1.0
        self.firing = self.firing or altitude + self.bias <= needed
        if self.firing and descent > 1.5:
            return GRAVITY + DECELERATION
        return GRAVITY if descent > 1.5 else GRAVITY - 1.0


CONFIG = ShieldConfig(
    observation=ObservationSpec(
        names=("altitude", "descent"), low=(0.0, -5.0), high=(150.0, 20.0), knee=()
    ),
    action=ActionSpec(low=0.0, high=THRUST_MAX, step=1.0),
    criteria=(Criterion("hard_landing", "increase"), Criterion("climb", "decrease")),
)

WORLD = World(
    name="tuning-lander",
    make=lambda seed: Lander(),
    controller=LateFiring,
    config=CONFIG,
    event=lambda obs, info: info["event"],
    shield_observation=lambda obs: [float(v) for v in obs],
    max_steps=1200,
)
