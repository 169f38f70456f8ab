"""Held-out world (a): car following of another make than ``client/sim``.

A lead cruises at 20-30 m/s with small speed noise and, at random moments (about one every
20 s), brakes hard at 5-7 m/s^2 for 1-2.5 s. The ego is driven by a controller that reacts a
second late: it sees the gap and speeds of 1 s ago, tracks a 0.8 s time gap with a
proportional law and brakes at most 4 m/s^2. Time step 0.1 s; ego acceleration in [-6, 3]
m/s^2; the shield observes ``[gap, ego speed, lead speed]`` (an order of its own). Failures:
``collision`` (gap <= 0) and ``lost`` (gap > 150 m). Episodes last at most 60 s. Not used to
choose any default.
"""

from __future__ import annotations

from collections import deque
from typing import Any

import numpy as np

from app.core import ActionSpec, Bound, Criterion, ObservationSpec, ShieldConfig
from bench.worlds.harness import World

DT = 0.1  # [s]
DELAY = 10  # steps: the controller's 1 s reaction lag
A_LOW, A_HIGH = -6.0, 3.0  # [m/s^2]


class BrakingLead:
    """The environment: reset/step like Gymnasium, with ``info["event"]``."""

    def __init__(self) -> None:
        self.rng = np.random.default_rng(0)
        self.gap = self.v = self.v_lead = 0.0
        self.cruise = 25.0
        self.braking = 0  # steps of hard braking left
        self.decel = 0.0

    def reset(self, seed: int | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        self.rng = np.random.default_rng(seed)
        self.cruise = float(self.rng.uniform(20, 30))
        self.v_lead = self.cruise
        self.v = self.v_lead + float(self.rng.uniform(-3, 3))
        self.gap = float(self.rng.uniform(20, 50))
        self.braking = 0
        return self._obs(), {"event": None}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        a = float(np.clip(np.asarray(action).reshape(-1)[0], A_LOW, A_HIGH))
        if self.braking == 0 and self.rng.random() < DT / 20.0:
            self.braking = int(self.rng.integers(10, 26))
            self.decel = float(self.rng.uniform(5, 7))
        if self.braking:
            a_lead = -self.decel
            self.braking -= 1
        else:
            a_lead = 0.5 * (self.cruise - self.v_lead) + float(self.rng.normal(0, 0.3))
        self.v_lead = max(0.0, self.v_lead + a_lead * DT)
        self.v = max(0.0, self.v + a * DT)
        self.gap += (self.v_lead - self.v) * DT
        event = "collision" if self.gap <= 0 else "lost" if self.gap > 150 else None
        return self._obs(), 0.0, event is not None, False, {"event": event}

    def _obs(self) -> np.ndarray:
        return np.array([self.gap, self.v, self.v_lead])


class LateController:
    """Tracks a 0.8 s time gap on what it saw a second ago and never brakes harder than
    4 m/s^2 (the car can do 6)."""

    def __init__(self, seed: int) -> None:
        self.seen: deque[np.ndarray] = deque(maxlen=DELAY + 1)

    def reset(self) -> None:
        self.seen.clear()

    def __call__(self, obs: np.ndarray) -> float:
        self.seen.append(obs.copy())
        gap, v, v_lead = self.seen[0]
        return float(np.clip(0.4 * (gap - 0.8 * v - 3.0) + 1.2 * (v_lead - v), -4.0, A_HIGH))


CONFIG = ShieldConfig(
    observation=ObservationSpec(
        names=("gap", "v_ego", "v_lead"), low=(0.0, 0.0, 0.0), high=(150.0, 35.0, 35.0), knee=()
    ),
    action=ActionSpec(low=A_LOW, high=A_HIGH, step=0.5),
    # the collision's bound declared, as the car-following default does (and not the lost
    # lead's, as the default does not bound falling behind)
    criteria=(
        Criterion("collision", "decrease", Bound("gap", below=0.0)),
        Criterion("lost", "increase"),
    ),
)

WORLD = World(
    name="braking-lead",
    make=lambda seed: BrakingLead(),
    controller=LateController,
    config=CONFIG,
    event=lambda obs, info: info["event"],
    shield_observation=lambda obs: [float(v) for v in obs],
    max_steps=600,
)
