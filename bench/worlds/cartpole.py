"""Tuning world for #68 (an unstable system whose saving direction depends on the state): a
pole balanced on a cart that is sent along a short track.

A pole is hinged on a cart that a motor pushes along a track. The pole is an inverted
pendulum: to catch it as it falls to one side, the cart must be pushed to that side, under
it, which carries the cart towards that side's end of the track; and to move the cart the
other way, the pole must first be tipped that way, by pushing the cart away from where it is
to go. So the push that saves the pole from falling right is the one that drives the cart off
the track's right end. The action is the motor's force, in [-10, 10] N (positive: right).
The cart is sent to a new position on the track every 2-4 s, and now and then (1% of steps)
something knocks the pole (an angular velocity of up to 0.5 rad/s either way). Failures:
``fall_right`` / ``fall_left`` (the pole more than 0.21 rad from upright to that side; fought
by pushing that way: a higher / lower force) and ``off_right`` / ``off_left`` (the cart more
than 1.2 m from the track's centre, past its end; fought in the end by pushing back: lower /
higher).

The equations of motion are those of the classic cart-pole (A. G. Barto, R. S. Sutton and
C. W. Anderson 1983, as in Gymnasium's CartPole), with no friction: a cart of 1 kg, a pole of
0.1 kg whose centre of mass is 0.5 m above the hinge; theta'' = (g sin theta - cos theta
(F + m l theta'^2 sin theta)/M) / (l (4/3 - m cos^2 theta / M)), x'' = (F + m l (theta'^2
sin theta - theta'' cos theta)) / M, with M the total mass. Here the motor follows the force
asked with a lag of 0.03 s, and the physics is integrated in two semi-implicit Euler steps
per step.

The controller is a hand-tuned linear state feedback (the form an LQR design gives): force =
k_a (theta + tilt) + k_w theta' + k_x e + k_v x', with e the cart's distance from its target
clipped to +-0.5 m (so that a far target is approached steadily), on what it saw a reaction
time ago (0.02-0.06 s, drawn per episode). Its gains are drawn per episode about a design
that balances the pole with a wide margin: the angle gains 0.6-2 times it, the position gains
0.3-1.8 times it (log-uniform). Its angle sensor is mounted off true by a tilt drawn per
episode (up to 0.025 rad either way), which it holds the pole against by keeping the cart
away from its target, the further the weaker its position gains, past the track's end when
the target lies near one: ``off_right`` / ``off_left``. Strong position gains or a long
reaction time against weak angle gains let a target's change or a knock tip the pole over:
``fall_right`` / ``fall_left``. Time step 0.02 s; at most 400 steps (8 s), ending at the
first failure.

The shield observes ``[position, velocity, angle, angular velocity, target]``: m, m/s, rad
(positive: leaning right), rad/s and m. The controller's task figure (``info["task"]``, per
step) is the distance from the cart to its target, in m. A tuning world: defaults may be
chosen on it (bench/worlds/tuning.py); calibrated alone to fail in about 44% of episodes
(seeds 0-8), 57% of them falls.
"""

from __future__ import annotations

import math
from collections import deque
from typing import Any

import numpy as np
from gymnasium.spaces import Box

from app.core import Bound, ShieldConfig
from bench.worlds.harness import Spaces, plain_world
from client.shield.spaces import config_for

DT = 0.02  # [s]
SUBSTEPS = 2  # semi-implicit Euler steps per step
MAX_STEPS = 400  # 8 s
GRAVITY = 9.81  # [m/s^2]
CART = 1.0  # [kg]
POLE = 0.1  # [kg]
HALF_LENGTH = 0.5  # [m] the hinge to the pole's centre of mass
FORCE_MAX = 10.0  # [N]
MOTOR_LAG = 0.03  # [s]
FALL = 0.21  # [rad] about 12 degrees
EDGE = 1.2  # [m] the track's half-length
TARGETS = 0.9  # [m] the targets lie within +-TARGETS of the centre
TARGET_EVERY = (100, 200)  # [steps] how long each target holds
KNOCK = 0.5  # [rad/s] the largest knock
KNOCK_CHANCE = 0.01  # per step
TILT = 0.025  # [rad] the largest offset of the controller's angle sensor
REACH = 0.5  # [m] the controller's position error is clipped to +-REACH
DESIGN = (40.0, 8.0, 3.0, 5.0)  # k_a [N/rad], k_w [N s/rad], k_x [N/m], k_v [N s/m]


class CartPole:
    """The environment: reset/step like Gymnasium, with ``info["event"]`` and
    ``info["task"]``."""

    def __init__(self) -> None:
        self.rng = np.random.default_rng(0)
        self.x = self.v = self.theta = self.omega = self.force = self.target = 0.0
        self.target_left = 0

    def reset(self, seed: int | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        self.rng = np.random.default_rng(seed)
        self.x = float(self.rng.uniform(-0.3, 0.3))
        self.v = float(self.rng.uniform(-0.1, 0.1))
        self.theta = float(self.rng.uniform(-0.05, 0.05))
        self.omega = float(self.rng.uniform(-0.1, 0.1))
        self.force = 0.0
        self._new_target()
        return self._obs(), {"event": None, "task": abs(self.x - self.target)}

    def _new_target(self) -> None:
        self.target = float(self.rng.uniform(-TARGETS, TARGETS))
        self.target_left = int(self.rng.integers(*TARGET_EVERY))

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        asked = min(max(float(np.asarray(action).reshape(-1)[0]), -FORCE_MAX), FORCE_MAX)
        h = DT / SUBSTEPS
        total = CART + POLE
        for _ in range(SUBSTEPS):
            self.force += (asked - self.force) * min(h / MOTOR_LAG, 1.0)
            sin, cos = math.sin(self.theta), math.cos(self.theta)
            push = (self.force + POLE * HALF_LENGTH * self.omega**2 * sin) / total
            alpha = (GRAVITY * sin - cos * push) / (
                HALF_LENGTH * (4.0 / 3.0 - POLE * cos**2 / total)
            )
            accel = push - POLE * HALF_LENGTH * alpha * cos / total
            self.v += accel * h
            self.x += self.v * h
            self.omega += alpha * h
            self.theta += self.omega * h
        if self.rng.random() < KNOCK_CHANCE:
            self.omega += float(self.rng.uniform(-KNOCK, KNOCK))
        self.target_left -= 1
        if self.target_left == 0:
            self._new_target()
        event = (
            "fall_right"
            if self.theta > FALL
            else "fall_left"
            if self.theta < -FALL
            else "off_right"
            if self.x > EDGE
            else "off_left"
            if self.x < -EDGE
            else None
        )
        return (
            self._obs(),
            0.0,
            event is not None,
            False,
            {"event": event, "task": abs(self.x - self.target)},
        )

    def _obs(self) -> np.ndarray:
        return np.array([self.x, self.v, self.theta, self.omega, self.target])


class Balancer:
    """Force ``k_a (theta + tilt) + k_w theta' + k_x e + k_v x'``, clipped, with e the
    distance to the target clipped to +-``REACH``, on the observation of a reaction time ago;
    the gains, the sensor's tilt and the reaction time are drawn per episode (the
    imperfection the shield is there to catch)."""

    def __init__(self, seed: int) -> None:
        self.rng = np.random.default_rng(seed)
        self.gains = DESIGN
        self.angle = self.position = 1.0  # the gains' factors over the design's
        self.tilt = 0.0  # [rad] the angle sensor's offset
        self.seen: deque[np.ndarray] = deque(maxlen=1)

    def reset(self) -> None:
        self.angle = float(np.exp(self.rng.uniform(np.log(0.6), np.log(2.0))))
        self.position = float(np.exp(self.rng.uniform(np.log(0.3), np.log(1.8))))
        k_a, k_w, k_x, k_v = DESIGN
        self.gains = (self.angle * k_a, self.angle * k_w, self.position * k_x, self.position * k_v)
        self.tilt = float(self.rng.uniform(-TILT, TILT))
        self.seen = deque(maxlen=int(self.rng.integers(1, 4)) + 1)

    def __call__(self, obs: np.ndarray) -> float:
        self.seen.append(np.array(obs, dtype=np.float64))
        x, v, theta, omega, target = self.seen[0]
        k_a, k_w, k_x, k_v = self.gains
        error = min(max(x - target, -REACH), REACH)
        force = k_a * (theta + self.tilt) + k_w * omega + k_x * error + k_v * v
        return min(max(float(force), -FORCE_MAX), FORCE_MAX)


# What a new user writes (client.shield.config_for): the ranges the observation usually
# takes, the force's range in 20 bins, and each failure with the direction of force that
# moves away from it; the second adds where each failure lies.
SPACES = Spaces(
    observation_space=Box(
        low=np.array([-EDGE, -2.0, -FALL, -2.0, -TARGETS]),
        high=np.array([EDGE, 2.0, FALL, 2.0, TARGETS]),
        dtype=np.float64,
    ),
    action_space=Box(low=-FORCE_MAX, high=FORCE_MAX, shape=(1,), dtype=np.float64),
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
        "fall_right": ("increase", Bound("x2", above=FALL)),
        "fall_left": ("decrease", Bound("x2", below=-FALL)),
        "off_right": ("decrease", Bound("x0", above=EDGE)),
        "off_left": ("increase", Bound("x0", below=-EDGE)),
    },
)


WORLD = plain_world("tuning-cartpole", CartPole, Balancer, CONFIG, MAX_STEPS)
WORLD_BOUNDED = plain_world("tuning-cartpole-bounded", CartPole, Balancer, BOUNDED, MAX_STEPS)
