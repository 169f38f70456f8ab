"""Held-out world for #68 (an unstable system whose saving direction depends on the state):
a bicycle ridden along a narrow track in a gusty side wind.

The bicycle is an inverted pendulum balanced by steering: steering into a lean swings the
wheels back under the rider and rights the bicycle, but it also turns the bicycle towards
that side. So the action that saves it from falling to one side first carries it towards
that side's edge of the track, and to leave an edge the rider must first steer towards it
(to lean away), then away. The action is the steering angle asked, in [-0.3, 0.3] rad
(positive: right), which the fork follows with a lag of 0.04 s. Gusts of side wind push the
lean. Failures: ``fall_right`` / ``fall_left`` (a lean beyond 0.5 rad to that side, fought by
steering that way: a higher / lower action) and ``off_right`` / ``off_left`` (more than
0.8 m from the track's centre, fought in the end by steering away: lower / higher).

Linearised point-mass bicycle (K. J. Astrom et al., "Bicycle dynamics and control", IEEE
Control Systems 2005, the simplest model): lean phi'' = (g/h) sin phi - (v^2 / (h b)) delta
cos phi + wind; heading psi' = v delta / b; offset y' = v sin psi, with the centre of mass
h = 1 m up, wheelbase b = 1 m and a speed v of 4.5 m/s.

The rider steers into the lean and its rate, and back to the track's centre by leaning
towards it, on what they saw a reaction time ago; the reaction time (0.05 or 0.1 s) and the
gains are drawn per episode, and now and then (1% of steps) the rider looks away and holds the
bars for 0.2-0.5 s. Time step 0.05 s; at most 300 steps (15 s), ending at the first failure.
The shield observes ``[lean, lean rate, heading, offset]`` in rad, rad/s, rad and m. The
controller's task figure (``info["task"]``, per step) is the absolute offset from the centre,
in m. Held out: not used to choose any default (bench/heldout/README.md).
"""

from __future__ import annotations

import math
from collections import deque
from typing import Any

import numpy as np
from gymnasium.spaces import Box

from app.core import Bound, ShieldConfig
from bench.worlds.harness import Spaces, World
from client.shield.spaces import config_for

DT = 0.05  # [s]
MAX_STEPS = 300  # 15 s
GRAVITY = 9.81  # [m/s^2]
HEIGHT = 1.0  # [m] the centre of mass above the ground
WHEELBASE = 1.0  # [m]
SPEED = 4.5  # [m/s]
FORK_LAG = 0.04  # [s] the fork's time constant
STEER_MAX = 0.3  # [rad]
FALL = 0.5  # [rad] the lean beyond which the bicycle falls
EDGE = 0.8  # [m] the track's half-width
GUST = 0.3  # [rad/s^2] the side wind's standard deviation on the lean


class Bicycle:
    """The environment: reset/step like Gymnasium, with ``info["event"]`` and
    ``info["task"]``."""

    def __init__(self) -> None:
        self.rng = np.random.default_rng(0)
        self.lean = self.rate = self.heading = self.offset = self.steer = self.wind = 0.0

    def reset(self, seed: int | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        self.rng = np.random.default_rng(seed)
        self.lean = float(self.rng.uniform(-0.05, 0.05))
        self.rate = float(self.rng.uniform(-0.1, 0.1))
        self.heading = float(self.rng.uniform(-0.05, 0.05))
        self.offset = float(self.rng.uniform(-0.3, 0.3))
        self.steer = 0.0
        self.wind = 0.0
        return self._obs(), {"event": None, "task": abs(self.offset)}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        asked = min(max(float(np.asarray(action).reshape(-1)[0]), -STEER_MAX), STEER_MAX)
        # the wind: a gust process with a correlation time of 0.5 s
        self.wind += -self.wind * DT / 0.5 + GUST * math.sqrt(2.0 * DT / 0.5) * float(
            self.rng.normal()
        )
        self.steer += (asked - self.steer) * DT / FORK_LAG
        # lean: phi'' = (g/h) sin phi - (v^2/(h b)) delta cos phi + wind
        accel = (
            GRAVITY / HEIGHT * math.sin(self.lean)
            - SPEED**2 / (HEIGHT * WHEELBASE) * self.steer * math.cos(self.lean)
            + self.wind
        )
        self.rate += accel * DT
        self.lean += self.rate * DT
        self.heading += SPEED * self.steer / WHEELBASE * DT  # psi' = v delta / b
        self.offset += SPEED * math.sin(self.heading) * DT  # y' = v sin psi
        event = None
        if abs(self.lean) > FALL:
            event = "fall_right" if self.lean > 0 else "fall_left"
        elif abs(self.offset) > EDGE:
            event = "off_right" if self.offset > 0 else "off_left"
        return (
            self._obs(),
            0.0,
            event is not None,
            False,
            {"event": event, "task": abs(self.offset)},
        )

    def _obs(self) -> np.ndarray:
        return np.array([self.lean, self.rate, self.heading, self.offset])


class Rider:
    """Steers ``k (lean - lean wanted) + d lean rate``, where the lean wanted takes the
    bicycle back to the centre (``-(p offset + q heading)``), on what they saw a reaction time
    ago; the reaction time and the gains are drawn per episode, and now and then the rider
    holds the bars."""

    def __init__(self, seed: int) -> None:
        self.rng = np.random.default_rng(seed)
        self.seen: deque[np.ndarray] = deque(maxlen=1)
        self.k = self.d = self.p = self.q = 0.0
        self.held = 0
        self.last = 0.0

    def reset(self) -> None:
        delay = int(self.rng.integers(1, 3))  # [steps] 0.05-0.1 s
        self.seen = deque(maxlen=delay + 1)
        self.k = float(self.rng.uniform(1.3, 2.0))  # [rad/rad]
        self.d = float(self.rng.uniform(0.4, 0.7))  # [rad s/rad]
        self.p = float(self.rng.uniform(0.04, 0.12))  # [rad/m]
        self.q = float(self.rng.uniform(0.4, 0.7))  # [rad/rad]
        self.held, self.last = 0, 0.0

    def __call__(self, obs: np.ndarray) -> float:
        self.seen.append(np.array(obs, dtype=np.float64))
        if self.held > 0:
            self.held -= 1
            return self.last
        if self.rng.random() < 0.01:
            self.held = int(self.rng.integers(4, 11))
        lean, rate, heading, offset = self.seen[0]
        wanted = -(self.p * offset + self.q * heading)
        self.last = min(max(self.k * (lean - wanted) + self.d * rate, -STEER_MAX), STEER_MAX)
        return self.last


# What a new user writes (client.shield.config_for): the ranges the observation usually
# takes, the steering's range in 20 bins, and each failure with the direction of steering
# that moves away from it; the second adds where each failure lies.
SPACES = Spaces(
    observation_space=Box(
        low=np.array([-FALL, -3.0, -0.6, -EDGE]),
        high=np.array([FALL, 3.0, 0.6, EDGE]),
        dtype=np.float64,
    ),
    action_space=Box(low=-STEER_MAX, high=STEER_MAX, shape=(1,), dtype=np.float64),
)
CONFIG: ShieldConfig = config_for(
    SPACES,
    {
        "fall_right": "increase",
        "fall_left": "decrease",
        "off_right": "decrease",
        "off_left": "increase",
    },
)
BOUNDED: ShieldConfig = config_for(
    SPACES,
    {
        "fall_right": ("increase", Bound("x0", above=FALL)),
        "fall_left": ("decrease", Bound("x0", below=-FALL)),
        "off_right": ("decrease", Bound("x3", above=EDGE)),
        "off_left": ("increase", Bound("x3", below=-EDGE)),
    },
)


def _world(name: str, config: ShieldConfig) -> World:
    return World(
        name=name,
        make=lambda seed: Bicycle(),
        controller=Rider,
        config=config,
        event=lambda obs, info: info["event"],
        shield_observation=lambda obs: [float(v) for v in obs],
        max_steps=MAX_STEPS,
    )


WORLD = _world("bicycle", CONFIG)
WORLD_BOUNDED = _world("bicycle-bounded", BOUNDED)
