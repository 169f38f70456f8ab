"""Held-out world for #68, fourth set (an unstable system whose saving direction depends on the
state): a gyroscopic monorail car, balanced on its single rail by a gyroscope whose gimbal
must not reach its stops.

A car of 3 t (and 0-800 kg of passengers, drawn per episode) runs at 8-14 m/s (drawn) on a
single rail, its centre of gravity about a metre above it: upright, it is an inverted
pendulum, and left alone it topples within a second or two. It is held up as Louis Brennan's
monorail of 1909 was: a heavy gyroscope spinning about a horizontal, transverse axle, in a
gimbal that turns about a vertical one. Turning (precessing) the gimbal makes the gyroscope
push on the car in roll, with a torque its angular momentum times the precession rate times
the cosine of the gimbal's angle. The action is the precession rate asked of the gimbal's
motor, in [-0.4, 0.4] rad/s (positive turns the gyroscope's axle towards the front), which the
motor follows within 0.05 s. The gyroscope can push only while it precesses: to hold the car
against a steady lean, the gimbal must keep turning, towards its stops, and to bring it back
the controller must let the car lean the other way, so that gravity does the pushing. So the
precession that saves the car from toppling to one side drives the gimbal towards a stop, and
bringing the gimbal back from a stop tips the car; which is nearer depends on the state. The
track bends (two waves of bends, drawn per episode, each of up to 0.8 m/s^2 of centripetal
acceleration), the car must lean into them, gusts push it sideways (800 N m of roll torque,
standard deviation, correlated over 2 s), and now and then (about one in 5 s) a passenger
moves across the car, shifting its centre of gravity by up to 4 cm. Failures: ``tip_left``
(the car leaning more than 0.2 rad to the left, beyond which the gyroscope cannot bring it
back; fought by a higher action), ``tip_right`` (to the right; lower), ``gimbal_fore`` (the
gimbal past 1.1 rad towards the front, onto its stop: the gyroscope jammed can push no more;
lower), and ``gimbal_aft`` (towards the back; higher). With the gimbal held still, a car
started near upright topples within 0.75-2 s (5th-95th percentile, median 1.1 s).

The model: roll lean phi (positive, left) and gimbal angle alpha, I phi'' = m g (h sin phi +
e) - m h a cos phi - H cos(alpha) alpha' - c phi' + w, with m the car's mass and h its centre of
gravity's height (both with the passengers), I = m (h^2 + 0.9^2) its inertia in roll about the
rail, e the passengers' offset, a the track's centripetal acceleration (positive, a bend to the
left), w the gusts' torque, H = 20000 N m s the gyroscope's angular momentum (Brennan's car
carried two rotors of 0.75 t spinning at 3000 rpm), c = 300 N m s its roll damping; the
gimbal's rate alpha' follows the rate asked with a lag of 0.05 s.

The controller is a balance loop of the usual kind for a control-moment gyroscope: it asks the
gimbal the precession whose roll torque cancels the toppling it expects of an empty car and
pulls the lean towards the lean it asks, with damping on the roll rate; and it asks a lean
that moves the gimbal back towards its centre, in proportion to the gimbal's angle. Its three
gains are drawn per episode (log-uniform: the lean's stiffness 0.8-2.5 times the empty car's
toppling stiffness, its damping 3-8 /s, the lean asked 0.04-0.6 rad per rad of gimbal): a
loop now well tuned, now too slow to bring the gimbal back before a bend runs it to a stop,
now so keen on the gimbal that the car rocks itself over. Its inclinometer's level is off by
up to 0.01 rad and its readings come 0-0.1 s late (both drawn per episode), and it does not
know the passengers' weight. Time step 0.05 s; an episode runs for at most 300 steps (15 s,
120-210 m), ending at the first failure. The shield observes ``[lean, roll rate, gimbal angle,
precession rate]`` in rad, rad/s, rad and rad/s. The controller's task figure
(``info["task"]``, per step) is the sideways acceleration the passengers feel, |a cos phi - g
sin phi|, in m/s^2. Held out: not used to choose any default (bench/heldout4/README.md).
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

DT = 0.05  # [s]
SUBSTEPS = 3  # Euler steps of the motion per step
MAX_STEPS = 300  # 15 s
G = 9.81  # [m/s^2]
MASS = 3000.0  # [kg] the car, empty
LOAD = (0.0, 800.0)  # [kg] its passengers, per episode
HEIGHT = 1.0  # [m] the empty car's centre of gravity above the rail
LOAD_HEIGHT = 1.3  # [m] the passengers'
GYRATION = 0.9  # [m] the car's radius of gyration about its centre of gravity, in roll
SPIN = 20000.0  # [N m s] the gyroscope's angular momentum
RATE_MAX = 0.4  # [rad/s] the gimbal motor's fastest precession
SERVO = 0.05  # [s] the gimbal motor's answer
DAMPING = 300.0  # [N m s/rad] the roll's damping
TIP = 0.2  # [rad] the lean beyond which the gyroscope cannot bring the car back
STOP = 1.1  # [rad] the gimbal's stops
SPEED = (8.0, 14.0)  # [m/s] per episode
BEND_ACCELERATION = 0.8  # [m/s^2] the largest centripetal acceleration of each wave of bends
BEND_LENGTH = (80.0, 250.0)  # [m] their wavelengths
WIND = 800.0  # [N m] the gusts' roll torque, standard deviation
WIND_TIME = 2.0  # [s] their correlation time
SHIFT_CHANCE = 0.01  # [1/step] a passenger moves across the car
SHIFT = 0.04  # [m] the largest move of the centre of gravity it brings
DELAY = (1, 4)  # [steps] the sensors' reading is this many steps old less one, per episode
LEVEL = 0.01  # [rad] the largest error of the inclinometer's level, per episode
KP = (0.8, 2.5)  # the lean's stiffness, in units of the nominal car's toppling stiffness
KD = (3.0, 8.0)  # [1/s] the roll rate's damping, per unit of the nominal inertia
KA = (0.04, 0.6)  # [rad/rad] the lean asked per rad of gimbal angle, per episode


class Monorail:
    """The environment: reset/step like Gymnasium, with ``info["event"]`` and
    ``info["task"]``."""

    def __init__(self) -> None:
        self.rng = np.random.default_rng(0)
        self.lean = self.roll_rate = self.gimbal = self.precession = 0.0
        self.wind = self.offset = self.distance = self.speed = 0.0
        self.mass = self.height = self.inertia = 0.0
        self.bends: list[tuple[float, float, float]] = []

    def reset(self, seed: int | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        self.rng = np.random.default_rng(seed)
        load = float(self.rng.uniform(*LOAD))
        self.mass = MASS + load
        self.height = (MASS * HEIGHT + load * LOAD_HEIGHT) / self.mass
        self.inertia = self.mass * (self.height**2 + GYRATION**2)
        self.speed = float(self.rng.uniform(*SPEED))
        self.bends = []  # centripetal acceleration [m/s^2], wavenumber [1/m], phase
        for _ in range(2):
            self.bends.append(
                (
                    float(self.rng.uniform(0.0, BEND_ACCELERATION)),
                    2.0 * math.pi / float(self.rng.uniform(*BEND_LENGTH)),
                    float(self.rng.uniform(0.0, 2.0 * math.pi)),
                )
            )
        self.distance = 0.0
        self.lean = float(self.rng.uniform(-0.02, 0.02))
        self.roll_rate = 0.0
        self.gimbal = float(self.rng.uniform(-0.1, 0.1))
        self.precession = 0.0
        self.wind = 0.0
        self.offset = float(self.rng.uniform(-SHIFT, SHIFT))
        return self._obs(), {"event": None, "task": self.felt()}

    def centripetal(self) -> float:
        """The track's centripetal acceleration [m/s^2], positive in a bend to the left."""
        return sum(a * math.sin(k * self.distance + p) for a, k, p in self.bends)

    def felt(self) -> float:
        """The sideways acceleration the passengers feel [m/s^2]."""
        return abs(self.centripetal() * math.cos(self.lean) - G * math.sin(self.lean))

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        asked = min(max(float(np.asarray(action).reshape(-1)[0]), -RATE_MAX), RATE_MAX)
        self.wind += -self.wind * DT / WIND_TIME + WIND * math.sqrt(2.0 * DT / WIND_TIME) * float(
            self.rng.normal()
        )
        if self.rng.random() < SHIFT_CHANCE:
            self.offset = min(
                max(self.offset + float(self.rng.uniform(-SHIFT, SHIFT)), -SHIFT), SHIFT
            )
        h = DT / SUBSTEPS
        for _ in range(SUBSTEPS):
            self.precession += (asked - self.precession) * h / SERVO
            torque = (
                self.mass * G * (self.height * math.sin(self.lean) + self.offset)
                - self.mass * self.height * self.centripetal() * math.cos(self.lean)
                - SPIN * math.cos(self.gimbal) * self.precession
                - DAMPING * self.roll_rate
                + self.wind
            )
            self.roll_rate += torque / self.inertia * h
            self.lean += self.roll_rate * h
            self.gimbal += self.precession * h
            self.distance += self.speed * h
        event = (
            "tip_left"
            if self.lean > TIP
            else "tip_right"
            if self.lean < -TIP
            else "gimbal_fore"
            if self.gimbal > STOP
            else "gimbal_aft"
            if self.gimbal < -STOP
            else None
        )
        return self._obs(), 0.0, event is not None, False, {"event": event, "task": self.felt()}

    def _obs(self) -> np.ndarray:
        return np.array([self.lean, self.roll_rate, self.gimbal, self.precession])


class Balancer:
    """The balance controller: precesses the gyroscope to give the roll torque that holds the
    lean asked against the toppling it expects of an empty car, and asks a lean that brings the
    gimbal back towards its centre, from late sensors and a misaligned inclinometer; the
    latency, the level's error and the gains are drawn per episode."""

    def __init__(self, seed: int) -> None:
        self.rng = np.random.default_rng(seed)
        self.kp = self.kd = self.ka = self.level = 0.0
        self.seen: deque[tuple[float, float, float]] = deque()
        self.delay = 1

    def reset(self) -> None:
        self.kp = float(np.exp(self.rng.uniform(*np.log(KP))))
        self.kd = float(np.exp(self.rng.uniform(*np.log(KD))))
        self.ka = float(np.exp(self.rng.uniform(*np.log(KA))))
        self.level = float(self.rng.uniform(-LEVEL, LEVEL))
        self.delay = int(self.rng.integers(*DELAY))
        self.seen = deque()

    def __call__(self, obs: np.ndarray) -> float:
        lean, roll_rate, gimbal, _ = (float(v) for v in obs)
        self.seen.append((lean + self.level, roll_rate, gimbal))
        if len(self.seen) > self.delay:
            self.seen.popleft()
        lean, roll_rate, gimbal = self.seen[0]
        stiffness = MASS * G * HEIGHT  # the empty car's toppling stiffness [N m/rad]
        inertia = MASS * (HEIGHT**2 + GYRATION**2)
        lean_asked = -self.ka * gimbal
        torque = (
            stiffness * math.sin(lean)
            + self.kp * stiffness * (lean - lean_asked)
            + self.kd * inertia * roll_rate
        )
        rate = torque / (SPIN * max(math.cos(gimbal), 0.3))
        return min(max(rate, -RATE_MAX), RATE_MAX)


# What a new user writes (client.shield.config_for): the ranges the observation usually
# takes, the precession's range in 20 bins, and each failure with the direction of the
# precession that moves away from it; the second adds where each failure lies.
SPACES = Spaces(
    observation_space=Box(
        low=np.array([-TIP, -0.5, -STOP, -RATE_MAX]),
        high=np.array([TIP, 0.5, STOP, RATE_MAX]),
        dtype=np.float64,
    ),
    action_space=Box(low=-RATE_MAX, high=RATE_MAX, shape=(1,), dtype=np.float64),
)
CONFIG: ShieldConfig = config_for(
    SPACES,
    {
        "tip_left": "increase",
        "tip_right": "decrease",
        "gimbal_fore": "decrease",
        "gimbal_aft": "increase",
    },
)
BOUNDED: ShieldConfig = config_for(
    SPACES,
    {
        "tip_left": ("increase", Bound("x0", above=TIP)),
        "tip_right": ("decrease", Bound("x0", below=-TIP)),
        "gimbal_fore": ("decrease", Bound("x2", above=STOP)),
        "gimbal_aft": ("increase", Bound("x2", below=-STOP)),
    },
)


WORLD = plain_world("monorail", Monorail, Balancer, CONFIG, MAX_STEPS)
WORLD_BOUNDED = plain_world("monorail-bounded", Monorail, Balancer, BOUNDED, MAX_STEPS)
