"""Held-out world (d): keeping a lane behind a drowsy driver, a lateral world.

A car holds its lane on a road whose bends push it sideways: a lateral disturbance that
changes every 2-6 s (uniform in +-1.2 m/s^2) with gusts on top (0.3 m/s^2 standard deviation).
The action is the lateral acceleration asked of the steering, which follows it with a lag
(time constant 0.3 s). The driver steers back towards the lane's centre on what they saw 0.8 s
before, and now and then stops correcting for 1-3 s, holding the wheel where it was; so the
car drifts out of the lane, and overshoots it. Failures: ``departure_left`` (more than 1.6 m
left of the centre, fought by steering right, a lower action) and ``departure_right``
(1.6 m to the right, fought by a higher one). Time step 0.1 s; action in [-3, 3] m/s^2;
episodes of at most 300 steps (30 s); the shield observes ``[offset, lateral speed, lateral
acceleration]``. Not used to choose any default.
"""

from __future__ import annotations

from collections import deque
from typing import Any

import numpy as np

from app.core import ActionSpec, Bound, Criterion, ObservationSpec, ShieldConfig
from bench.worlds.harness import World

DT = 0.1  # [s]
LAG = 0.3  # [s] the steering's time constant
EDGE = 1.6  # [m] from the lane's centre
A_MAX = 3.0  # [m/s^2]
KP, KD = 0.5, 1.0  # the driver's gains on the offset [1/s^2] and the lateral speed [1/s]


class Lane:
    """The environment: reset/step like Gymnasium, with ``info["event"]``."""

    def __init__(self) -> None:
        self.rng = np.random.default_rng(0)
        self.offset = self.speed = self.accel = self.push = 0.0
        self.bend_left = 0

    def reset(self, seed: int | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        self.rng = np.random.default_rng(seed)
        self.offset = float(self.rng.uniform(-0.5, 0.5))
        self.speed = float(self.rng.uniform(-0.3, 0.3))
        self.accel = 0.0
        self._bend()
        return self._obs(), {"event": None}

    def _bend(self) -> None:
        self.push = float(self.rng.uniform(-1.2, 1.2))
        self.bend_left = int(self.rng.integers(20, 61))

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        u = float(np.clip(np.asarray(action).reshape(-1)[0], -A_MAX, A_MAX))
        self.bend_left -= 1
        if self.bend_left == 0:
            self._bend()
        self.accel += (u - self.accel) * DT / LAG
        disturbance = self.push + float(self.rng.normal(0.0, 0.3))
        self.speed += (self.accel + disturbance) * DT
        self.offset += self.speed * DT
        event = (
            "departure_left"
            if self.offset > EDGE
            else "departure_right"
            if self.offset < -EDGE
            else None
        )
        return self._obs(), 0.0, event is not None, False, {"event": event}

    def _obs(self) -> np.ndarray:
        """The car's lateral state, then the bend's push (which the driver sees in the road
        ahead; the shield does not)."""
        return np.array([self.offset, self.speed, self.accel, self.push])


class DrowsyDriver:
    """Steers against the bend and back to the centre (proportional and derivative) on what
    it saw 0.8 s before, and now and then (1% of steps) holds the wheel for 1-3 s."""

    DELAY = 8  # steps

    def __init__(self, seed: int) -> None:
        self.rng = np.random.default_rng(seed)
        self.seen: deque[np.ndarray] = deque(maxlen=self.DELAY)
        self.held = 0
        self.last = 0.0

    def reset(self) -> None:
        self.seen.clear()
        self.held, self.last = 0, 0.0

    def __call__(self, obs: np.ndarray) -> float:
        self.seen.append(np.array(obs))
        if self.held > 0:
            self.held -= 1
            return self.last
        if self.rng.random() < 0.01:
            self.held = int(self.rng.integers(10, 31))
        offset, speed, _, push = self.seen[0]
        self.last = float(np.clip(-push - KP * offset - KD * speed, -A_MAX, A_MAX))
        return self.last


CONFIG = ShieldConfig(
    observation=ObservationSpec(
        names=("offset", "lateral_speed", "lateral_accel"),
        low=(-2.0, -3.0, -A_MAX),
        high=(2.0, 3.0, A_MAX),
        knee=(),
    ),
    action=ActionSpec(low=-A_MAX, high=A_MAX, step=0.3),
    criteria=(
        Criterion("departure_left", "decrease", Bound("offset", above=EDGE)),
        Criterion("departure_right", "increase", Bound("offset", below=-EDGE)),
    ),
)

WORLD = World(
    name="lane",
    make=lambda seed: Lane(),
    controller=DrowsyDriver,
    config=CONFIG,
    event=lambda obs, info: info["event"],
    shield_observation=lambda obs: [float(v) for v in obs[:3]],
    max_steps=300,
)
