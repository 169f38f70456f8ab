"""Tuning world: a tank kept between overflowing and running dry, of another make than the
car-following simulator and with few states, to choose defaults on (never a held-out world).

Water flows in at a rate that drifts and surges; a pump takes it out at the rate the
controller sets, in [0, 4] m^3/s. The controller pumps what it believes flows in plus a
correction towards half full, but it reads the level several seconds late and its gain is
drawn per episode, so it overshoots both ways. Failures: ``overflow`` (level above 10 m) and
``dry`` (below 0.5 m with the pump on). Time step 1 s; the shield observes
``[level, inflow]``.
"""

from __future__ import annotations

from collections import deque
from typing import Any

import numpy as np

from app.core import ActionSpec, Criterion, ObservationSpec, ShieldConfig
from bench.worlds.harness import World

AREA = 4.0  # [m^2]
DELAY = 8  # [steps] the controller's view of the level is this old
PUMP_MAX = 4.0  # [m^3/s]


class Tank:
    """The environment: reset/step like Gymnasium, with ``info["event"]``."""

    def __init__(self) -> None:
        self.rng = np.random.default_rng(0)
        self.level = self.inflow = self.base = 0.0
        self.surge = 0.0
        self.surge_left = 0

    def reset(self, seed: int | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        self.rng = np.random.default_rng(seed)
        self.level = float(self.rng.uniform(3.0, 7.0))
        self.base = float(self.rng.uniform(0.8, 2.0))
        self.surge, self.surge_left = 0.0, 0
        self.inflow = self.base
        return self._obs(), {"event": None}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        pump = float(np.clip(np.asarray(action).reshape(-1)[0], 0.0, PUMP_MAX))
        self.level += (self.inflow - pump) / AREA
        event = None
        if self.level > 10.0:
            event = "overflow"
        elif self.level < 0.5 and pump > 0.1:
            event = "dry"
        self.level = max(self.level, 0.0)
        self._next_inflow()
        return self._obs(), 0.0, event is not None, False, {"event": event}

    def _next_inflow(self) -> None:
        if self.surge_left > 0:
            self.surge_left -= 1
        elif self.rng.random() < 0.03:  # a surge (or, negative, a drought) begins
            self.surge = float(self.rng.choice([-1.0, 1.0]) * self.rng.uniform(0.5, 2.0))
            self.surge_left = int(self.rng.integers(10, 40))
        else:
            self.surge = 0.0
        self.base = float(np.clip(self.base + self.rng.normal(0.0, 0.03), 0.3, 2.5))
        self.inflow = max(0.0, self.base + self.surge)

    def _obs(self) -> np.ndarray:
        return np.array([self.level, self.inflow])


class LateValve:
    """Pumps the inflow it sees plus a gain times the level's error from half full, on a
    level read ``DELAY`` steps late; the gain is drawn per episode."""

    def __init__(self, seed: int) -> None:
        self.rng = np.random.default_rng(seed)
        self.seen: deque[float] = deque(maxlen=DELAY + 1)
        self.gain = 1.0

    def reset(self) -> None:
        self.seen.clear()
        self.gain = float(self.rng.uniform(0.5, 2.5))

    def __call__(self, obs: np.ndarray) -> float:
        level, inflow = obs
        self.seen.append(float(level))
        return float(np.clip(inflow + self.gain * (self.seen[0] - 5.0), 0.0, PUMP_MAX))


CONFIG = ShieldConfig(
    observation=ObservationSpec(
        names=("level", "inflow"), low=(0.0, 0.0), high=(10.0, 4.5), knee=()
    ),
    action=ActionSpec(low=0.0, high=PUMP_MAX, step=0.25),
    criteria=(Criterion("overflow", "increase"), Criterion("dry", "decrease")),
)

WORLD = World(
    name="tuning-tank",
    make=lambda seed: Tank(),
    controller=LateValve,
    config=CONFIG,
    event=lambda obs, info: info["event"],
    shield_observation=lambda obs: [float(v) for v in obs],
    max_steps=400,
)
