"""Held-out world (c): stop before a wall, in one dimension.

A car starts 150-250 m before a wall at 15-25 m/s. Its controller cruises, then brakes at
3 m/s^2 from the distance its speed needs, but it judges its speed 10-30% low (drawn per
episode), so it often starts braking too late; the car can brake at 8 m/s^2. Failures:
``crash`` (reaching the wall faster than 1 m/s) and ``short`` (stopping, below 0.5 m/s, more
than 15 m before the wall). Time step 0.1 s; acceleration in [-8, 2] m/s^2; the shield
observes ``[distance, speed]``. Not used to choose any default.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from app.core import ActionSpec, Criterion, ObservationSpec, ShieldConfig
from bench.worlds.harness import World

DT = 0.1  # [s]


class Wall:
    """The environment: reset/step like Gymnasium, with ``info["event"]``."""

    def __init__(self) -> None:
        self.rng = np.random.default_rng(0)
        self.distance = self.speed = 0.0
        self.misjudge = 1.0

    def reset(self, seed: int | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        self.rng = np.random.default_rng(seed)
        self.distance = float(self.rng.uniform(150, 250))
        self.speed = float(self.rng.uniform(15, 25))
        self.misjudge = float(self.rng.uniform(0.7, 0.9))
        return self._obs(), {"event": None, "misjudge": self.misjudge}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        a = float(np.clip(np.asarray(action).reshape(-1)[0], -8.0, 2.0))
        self.speed = max(0.0, self.speed + a * DT)
        self.distance -= self.speed * DT
        event = None
        if self.distance <= 0:
            event = "crash" if self.speed > 1.0 else None
        elif self.speed < 0.5 and self.distance > 15.0:
            event = "short"
        done = self.distance <= 0 or self.speed < 0.5
        return self._obs(), 0.0, done, False, {"event": event, "misjudge": self.misjudge}

    def _obs(self) -> np.ndarray:
        return np.array([self.distance, self.speed])


class LateBraker:
    """Cruises at its speed and brakes at 3 m/s^2 once the distance it believes it needs is
    reached, from a speed it judges too low by the episode's factor."""

    def __init__(self, seed: int) -> None:
        self.rng = np.random.default_rng(seed)
        self.factor = 0.8

    def reset(self) -> None:
        self.factor = float(self.rng.uniform(0.7, 0.9))

    def __call__(self, obs: np.ndarray) -> float:
        distance, speed = obs
        judged = speed * self.factor
        return -3.0 if distance <= judged**2 / 6.0 + 2.0 else 0.0


CONFIG = ShieldConfig(
    observation=ObservationSpec(
        names=("distance", "speed"), low=(0.0, 0.0), high=(250.0, 25.0), knee=()
    ),
    action=ActionSpec(low=-8.0, high=2.0, step=0.5),
    criteria=(Criterion("crash", "decrease"), Criterion("short", "increase")),
)

WORLD = World(
    name="wall",
    make=lambda seed: Wall(),
    controller=LateBraker,
    config=CONFIG,
    event=lambda obs, info: info["event"],
    shield_observation=lambda obs: [float(v) for v in obs],
    max_steps=600,
)
