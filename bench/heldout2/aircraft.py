"""Held-out world for #68, second set (an unstable system whose saving direction depends on
the state): a survey drone, its centre of gravity too far aft, flying low over hills in
gusty air.

A fixed-wing drone photographs a hilly country from 60 m above the ground at 22 m/s, over
three waves of hills (slopes up to 0.35 each, 300-1500 m long). It must stay above 10 m
(``ground``) and below 120 m above the ground, the top of the airspace it may use
(``ceiling``). Its camera payload is fitted anew for each flight and leaves the centre of
gravity too far aft, so that a nose that rises is pushed further up and a nose that drops
further down: a pitch stiffness drawn per flight in 0-35 1/s^2, which the pitch damping and
the wing's lift hold up to about 15 and which diverges beyond (on four flights in seven;
left with the elevator held, a drone of stiffness 25 stalls or pushes over within 1.5-6 s).
The action is the elevator asked of the servo, in [-0.3, 0.3] rad (positive pulls the nose
up), which the servo follows within 0.05 s. Pulling up climbs away from the ground but raises
the angle of attack towards the stall (and the tail's own lift first sinks the drone a
little); pushing over lowers the angle of attack but sinks the drone towards the ground.
So the elevator that saves it from one failure carries it towards another, and which is
nearer depends on the state. Failures: ``stall``, the angle of attack above 0.25 rad
(fought by pushing over, a lower action); ``negative_stall``, below -0.07 rad, the wing
unloaded and the payload thrown about (fought by pulling up, higher); ``ground`` (fought in
the end by pulling up, higher) and ``ceiling`` (fought by pushing over, lower). Vertical gusts
(0.8 m/s, correlated over 1 s) change the angle of attack.

The longitudinal model, linear in the angle of attack alpha = theta - gamma + w / V (pitch
theta, flight path gamma, vertical wind w), at a constant airspeed V held by the throttle:
pitch rate q' = M_alpha (alpha - alpha_0) + M_q q + M_delta delta; theta' = q; path
gamma' = (L_alpha alpha + L_delta delta - g cos gamma) / V; height above the ground h' =
V sin gamma - V cos gamma dz/dx over the terrain z(x) (the short-period and path equations
of B. Etkin and L. D. Reid, Dynamics of Flight, 1996), with alpha_0 = g / L_alpha = 0.09
rad the angle of attack of level flight.

The controller is the drone's autopilot, three loops tuned on the nominal payload: a height
loop asks a vertical speed in proportion to the gap between 60 m and the height read by a
radar altimeter that lags 0.3 s, within a limit the operator sets per flight (drawn in
2.5-5 m/s); a climb loop asks an angle of attack in proportion to the gap in vertical speed;
an inner loop moves the elevator on the gap in angle of attack and damps the pitch rate. Its
gains are drawn per flight. It never sees the terrain ahead, so a steep hillside outruns its
climb limit and a crest leaves it high, and on an unstable airframe a loop with too little
pitch damping or too keen a climb loop rings into a stall one way or the other. Time step
0.1 s; at most 300 steps (30 s, 660 m), ending at the first failure. The shield observes
``[angle of attack, pitch rate, vertical speed, height above the ground]`` in rad, rad/s, m/s
and m. The controller's task figure (``info["task"]``, per step) is the absolute gap between
the height above the ground and 60 m. Held out: not used to choose any default
(bench/heldout2/README.md).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from gymnasium.spaces import Box

from app.core import Bound, ShieldConfig
from bench.worlds.harness import Spaces, World
from client.shield.spaces import config_for

DT = 0.1  # [s]
SUBSTEPS = 5  # Euler steps of the flight per step
MAX_STEPS = 300  # 30 s
GRAVITY = 9.81  # [m/s^2]
SPEED = 22.0  # [m/s] the airspeed, held by the throttle
LIFT_SLOPE = 109.0  # [m/s^2 per rad] the wing's lift over the mass per radian of incidence
LIFT_ELEVATOR = -8.0  # [m/s^2 per rad] the tail's lift, down when the elevator pulls up
TRIM = GRAVITY / LIFT_SLOPE  # [rad] the angle of attack of level flight, 0.09
DAMPING = -3.0  # [1/s] M_q, the pitch damping
ELEVATOR_POWER = 40.0  # [rad/s^2 per rad] M_delta
STIFFNESS = (0.0, 35.0)  # [1/s^2] M_alpha, drawn per flight: positive is unstable
SERVO_LAG = 0.05  # [s] the elevator's servo
ELEVATOR_MAX = 0.3  # [rad]
STALL = 0.25  # [rad] the angle of attack at which the wing stalls
NEGATIVE_STALL = -0.07  # [rad] the angle of attack below which the wing is unloaded
GROUND = 10.0  # [m] the least height above the ground
CEILING = 120.0  # [m] the most height above the ground (the airspace's top)
SURVEY = 60.0  # [m] the height the survey is flown at
HILL_SLOPE = 0.35  # the steepest slope of each of three waves of hills
HILL_LENGTH = (300.0, 1500.0)  # [m] their wavelengths
GUST = 0.8  # [m/s] the vertical wind's standard deviation
GUST_TIME = 1.0  # [s] its correlation time
ALTIMETER_LAG = 0.3  # [s] the radar altimeter the autopilot reads
CLIMB_MAX = (2.5, 5.0)  # [m/s] the autopilot's limit on the vertical speed, per flight
K_HEIGHT = (0.1, 0.4)  # [1/s] the vertical speed asked per m of height gap, per flight
K_CLIMB = (1.0, 3.0)  # the angle of attack asked per radian of climb-angle gap, per flight
K_PITCH = (0.5, 1.5)  # [rad/rad] the elevator per radian of angle-of-attack gap, per flight
K_RATE = (0.12, 0.4)  # [rad s/rad] the elevator per rad/s of pitch rate, per flight


class Aircraft:
    """The environment: reset/step like Gymnasium, with ``info["event"]`` and
    ``info["task"]``."""

    def __init__(self) -> None:
        self.rng = np.random.default_rng(0)
        self.pitch = self.rate = self.path = self.height = self.distance = 0.0
        self.elevator = self.wind = self.stiffness = 0.0
        self.hills: list[tuple[float, float, float]] = []

    def reset(self, seed: int | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        self.rng = np.random.default_rng(seed)
        self.stiffness = float(self.rng.uniform(*STIFFNESS))
        # the terrain: three waves of hills, amplitude [m], wavenumber [1/m], phase
        self.hills = []
        for _ in range(3):
            length = float(self.rng.uniform(*HILL_LENGTH))  # [m]
            slope = float(self.rng.uniform(0.0, HILL_SLOPE))  # the wave's steepest slope
            self.hills.append(
                (
                    slope * length / (2.0 * math.pi),
                    2.0 * math.pi / length,
                    float(self.rng.uniform(0.0, 2.0 * math.pi)),
                )
            )
        self.distance = 0.0
        self.height = SURVEY + float(self.rng.uniform(-5.0, 5.0))
        self.path = float(self.rng.uniform(-0.05, 0.05))
        self.pitch = self.path + TRIM
        self.rate = self.elevator = self.wind = 0.0
        return self._obs(), {"event": None, "task": abs(self.height - SURVEY)}

    def slope(self) -> float:
        """The ground's slope under the aircraft [rad, up ahead positive]."""
        return math.atan(sum(a * k * math.cos(k * self.distance + p) for a, k, p in self.hills))

    def incidence(self) -> float:
        """The angle of attack [rad]: the pitch less the flight path, plus the vertical
        wind's share."""
        return self.pitch - self.path + self.wind / SPEED

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        asked = min(max(float(np.asarray(action).reshape(-1)[0]), -ELEVATOR_MAX), ELEVATOR_MAX)
        self.wind += -self.wind * DT / GUST_TIME + GUST * math.sqrt(2.0 * DT / GUST_TIME) * float(
            self.rng.normal()
        )
        h = DT / SUBSTEPS
        for _ in range(SUBSTEPS):
            self.elevator += (asked - self.elevator) * h / SERVO_LAG
            alpha = self.incidence()
            accel = (
                self.stiffness * (alpha - TRIM)
                + DAMPING * self.rate
                + ELEVATOR_POWER * self.elevator
            )
            lift = LIFT_SLOPE * alpha + LIFT_ELEVATOR * self.elevator
            climb = SPEED * math.sin(self.path)
            self.rate += accel * h
            self.pitch += self.rate * h
            self.path += (lift - GRAVITY * math.cos(self.path)) / SPEED * h
            self.height += (climb - SPEED * math.cos(self.path) * math.tan(self.slope())) * h
            self.distance += SPEED * math.cos(self.path) * h
        alpha = self.incidence()
        event = (
            "stall"
            if alpha > STALL
            else "negative_stall"
            if alpha < NEGATIVE_STALL
            else "ground"
            if self.height < GROUND
            else "ceiling"
            if self.height > CEILING
            else None
        )
        return (
            self._obs(),
            0.0,
            event is not None,
            False,
            {"event": event, "task": abs(self.height - SURVEY)},
        )

    def _obs(self) -> np.ndarray:
        return np.array([self.incidence(), self.rate, SPEED * math.sin(self.path), self.height])


class Autopilot:
    """Elevator ``k_pitch (alpha asked - alpha) - k_rate q``, where the angle of attack asked
    is the level one plus ``k_climb`` times the gap in climb angle, and the vertical speed
    asked is ``k_height`` times the gap to the survey height on a lagging altimeter, within
    ``climb_max``; the gains and the limit are drawn per flight."""

    def __init__(self, seed: int) -> None:
        self.rng = np.random.default_rng(seed)
        self.k_height = self.k_climb = self.k_pitch = self.k_rate = 0.0
        self.read: float | None = None
        self.climb_max = 0.0

    def reset(self) -> None:
        self.k_height = float(self.rng.uniform(*K_HEIGHT))
        self.k_climb = float(self.rng.uniform(*K_CLIMB))
        self.k_pitch = float(self.rng.uniform(*K_PITCH))
        self.k_rate = float(self.rng.uniform(*K_RATE))
        self.read = None
        self.climb_max = float(self.rng.uniform(*CLIMB_MAX))

    def __call__(self, obs: np.ndarray) -> float:
        alpha, rate, climb, height = (float(v) for v in obs)
        # the radar altimeter: d read/dt = (height - read) / lag
        self.read = (
            height if self.read is None else self.read + (height - self.read) * DT / ALTIMETER_LAG
        )
        asked_climb = min(
            max(self.k_height * (SURVEY - self.read), -self.climb_max), self.climb_max
        )
        asked_alpha = TRIM + self.k_climb * (asked_climb - climb) / SPEED
        elevator = self.k_pitch * (asked_alpha - alpha) - self.k_rate * rate
        return min(max(elevator, -ELEVATOR_MAX), ELEVATOR_MAX)


# What a new user writes (client.shield.config_for): the ranges the observation usually
# takes, the elevator's range in 20 bins, and each failure with the direction of the elevator
# that moves away from it; the second adds where each failure lies.
SPACES = Spaces(
    observation_space=Box(
        low=np.array([NEGATIVE_STALL, -1.5, -8.0, 0.0]),
        high=np.array([STALL, 1.5, 8.0, CEILING]),
        dtype=np.float64,
    ),
    action_space=Box(low=-ELEVATOR_MAX, high=ELEVATOR_MAX, shape=(1,), dtype=np.float64),
)
CONFIG: ShieldConfig = config_for(
    SPACES,
    {
        "stall": "decrease",
        "negative_stall": "increase",
        "ground": "increase",
        "ceiling": "decrease",
    },
)
BOUNDED: ShieldConfig = config_for(
    SPACES,
    {
        "stall": ("decrease", Bound("x0", above=STALL)),
        "negative_stall": ("increase", Bound("x0", below=NEGATIVE_STALL)),
        "ground": ("increase", Bound("x3", below=GROUND)),
        "ceiling": ("decrease", Bound("x3", above=CEILING)),
    },
)


def _world(name: str, config: ShieldConfig) -> World:
    return World(
        name=name,
        make=lambda seed: Aircraft(),
        controller=Autopilot,
        config=config,
        event=lambda obs, info: info["event"],
        shield_observation=lambda obs: [float(v) for v in obs],
        max_steps=MAX_STEPS,
    )


WORLD = _world("aircraft", CONFIG)
WORLD_BOUNDED = _world("aircraft-bounded", BOUNDED)
