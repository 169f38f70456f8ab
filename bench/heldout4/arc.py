"""Held-out world for #68, fourth set (a runaway and an extinction on either side of an
unstable operating point): the direct-current carbon arc of an emission spectrograph, burning
a powdered sample in its anode's cup, held at the current asked by its rectifier's voltage.

A spectrographic laboratory burns a powdered rock sample in a DC arc between two graphite
electrodes, 3.5-4.5 mm apart (drawn per episode), to photograph its spectrum over a 25 s
exposure. The arc's voltage falls as its current grows (its column grows hotter and conducts
better): above the current that holds it, the voltage the arc needs falls below what the
supply gives and the current grows on, towards the rectifier's limit; below it, the arc needs
more than it gets and the current falls on until the arc goes out. A series choke (0.8-1.5 H,
drawn) slows this to seconds, and a resistance of 0.25 ohm in the leads is too small to
stabilise it. The action is the voltage asked of the rectifier, in [0, 100] V (about 55-65 V
holds the arc), which it delivers within 0.1 s. The analyst's programme asks 7-9 A first
(for the volatile elements) and then 9-12 A (for the refractory ones), reached in a ramp of
2 A/s after 4-14 s (all drawn per episode). The electrodes burn back (the gap grows by
0.02-0.08 mm/s, drawn), the arc wanders on them (0.15 mm standard deviation over 0.5 s),
grains of the sample spit and the arc's root jumps (about one every 2.5 s, lengthening or
shortening the arc by 0.3-1 mm, for 0.3 s), and as the sample's volatile elements distil
(at 2-15 s, for 3-8 s, drawn) their easily ionised vapour lowers the arc's voltage by up to
5-12 V. Failures: ``runaway``, the current above 15 A (the sample boils out of its cup and the
exposure is lost; fought by less voltage, a lower action), and ``extinction``, below 3 A (the
arc goes out; fought by more, higher). Left at the voltage that held it, an arc with 20% more
current runs away within 3.3-9.5 s (5th-95th percentile) and one with 20% less goes out
within 0.8-2.4 s, in all but one episode in 400 (with the gap and the sample held steady); with
no voltage the arc goes out, and with all of it runs away, within 0.2-0.4 s.

The model: Hertha Ayrton's law of the arc (The Electric Arc, 1902), V = A + B l + (C + D l) /
I with her carbon arc's A = 38.88 V, B = 2.074 V/mm, C = 11.66 V A and D = 10.54 V A/mm, l the
arc's length in mm and I its current in A, less the vapour's lowering; the circuit L dI/dt =
E - R I - V, E the rectifier's voltage. The arc's own thermal response, under a millisecond, is
taken as instant.

The controller is the rectifier's current regulator: the voltage its model of the arc (a 4 mm
arc, Ayrton's law) needs at the current asked, plus a correction in proportion to the gap
between the current asked and the current read, and to that gap's integral (no anti-windup).
It reads the current through a shunt whose filter lags 0.05-0.5 s (drawn per episode) and that
is calibrated within +-6% (drawn); its gains are drawn per episode (log-uniform, 0.7-8 V/A
and 0.2-4 V/(A s)): a loop now well tuned, now too timid to catch the instability, now so keen
that its lagging shunt makes it overshoot. Time step 0.1 s; an episode runs for at most 250
steps (25 s), ending at the first failure. The shield observes ``[current, arc voltage,
rectifier voltage, current asked]`` in A, V, V and A. The controller's task figure
(``info["task"]``, per step) is the absolute gap between the current and the current asked,
in A. Held out: not used to choose any default (bench/heldout4/README.md).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from gymnasium.spaces import Box

from app.core import Bound, ShieldConfig
from bench.worlds.harness import Spaces, plain_world
from client.shield.spaces import config_for

DT = 0.1  # [s]
SUBSTEPS = 5  # Euler steps of the circuit per step
MAX_STEPS = 250  # 25 s, an exposure
# Hertha Ayrton's carbon arc (The Electric Arc, 1902): V = A + B l + (C + D l) / I
A, B, C, D = 38.88, 2.074, 11.66, 10.54  # [V], [V/mm], [V A], [V A/mm]
RESISTANCE = 0.25  # [ohm] the leads, the carbons and the rectifier's own
CHOKE = (0.8, 1.5)  # [H] the smoothing choke, per episode
VOLTAGE_MAX = 100.0  # [V] the rectifier's highest output
RECTIFIER_LAG = 0.1  # [s] its answer
GAP = (3.5, 4.5)  # [mm] the gap the carbons are set to, per episode
BURN = (0.02, 0.08)  # [mm/s] the carbons burn back, per episode
WANDER = 0.15  # [mm] the arc's wander about the gap, standard deviation
WANDER_TIME = 0.5  # [s]
SPIT_CHANCE = 0.04  # [1/step] a grain of the sample spits, or the arc root jumps
SPIT = (0.3, 1.0)  # [mm] how much it lengthens or shortens the arc
SPIT_TIME = 0.3  # [s] its decay
VAPOUR = (5.0, 12.0)  # [V] how far the sample's volatile vapour lowers the arc's voltage
VAPOUR_START = (2.0, 15.0)  # [s] when the volatile elements distil, per episode
VAPOUR_LENGTH = (3.0, 8.0)  # [s] for how long
ASKED = ((7.0, 9.0), (9.0, 12.0))  # [A] the first and second current of the programme
STEP_AT = (40, 140)  # [steps] the step from the first to the second
RAMP = 2.0  # [A/s]
RUNAWAY = 15.0  # [A]
EXTINCTION = 3.0  # [A]
GAP_ASSUMED = 4.0  # [mm] the regulator's model of the arc
SHUNT_LAG = (0.05, 0.5)  # [s] the current measurement's filter, per episode
CALIBRATION = 0.06  # its largest calibration error, per episode
KP = (0.7, 8.0)  # [V/A] log-uniform per episode
KI = (0.2, 4.0)  # [V/(A s)] log-uniform per episode


def arc_voltage(current: float, length: float, vapour: float = 0.0) -> float:
    """The arc's voltage [V] at ``current`` [A] and ``length`` [mm], lowered by ``vapour``
    [V]."""
    return A - vapour + B * length + (C + D * length) / max(current, 0.5)


class Arc:
    """The environment: reset/step like Gymnasium, with ``info["event"]`` and
    ``info["task"]``."""

    def __init__(self) -> None:
        self.rng = np.random.default_rng(0)
        self.current = self.supply = self.gap = self.burn = self.wander = self.spit = 0.0
        self.choke = self.vapour = self.vapour_start = self.vapour_length = 0.0
        self.asked = self.first = self.second = 0.0
        self.step_at = self.steps = 0

    def reset(self, seed: int | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        self.rng = np.random.default_rng(seed)
        self.choke = float(self.rng.uniform(*CHOKE))
        self.gap = float(self.rng.uniform(*GAP))
        self.burn = float(self.rng.uniform(*BURN))
        self.vapour = float(self.rng.uniform(*VAPOUR))
        self.vapour_start = float(self.rng.uniform(*VAPOUR_START))
        self.vapour_length = float(self.rng.uniform(*VAPOUR_LENGTH))
        self.first = float(self.rng.uniform(*ASKED[0]))
        self.second = float(self.rng.uniform(*ASKED[1]))
        self.step_at = int(self.rng.integers(*STEP_AT))
        self.asked = self.first
        self.wander = self.spit = 0.0
        self.steps = 0
        self.current = self.first * (1.0 + float(self.rng.uniform(-0.03, 0.03)))
        self.supply = RESISTANCE * self.current + arc_voltage(self.current, self.length())
        return self._obs(), {"event": None, "task": abs(self.current - self.asked)}

    def length(self) -> float:
        """The arc's length [mm]."""
        return max(self.gap + self.wander + self.spit, 0.5)

    def lowered(self) -> float:
        """How far the sample's vapour lowers the arc's voltage now [V]."""
        t = self.steps * DT - self.vapour_start
        if t < 0.0 or t > self.vapour_length:
            return 0.0
        return self.vapour * math.sin(math.pi * t / self.vapour_length)

    def voltage(self) -> float:
        return arc_voltage(self.current, self.length(), self.lowered())

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        asked_voltage = min(max(float(np.asarray(action).reshape(-1)[0]), 0.0), VOLTAGE_MAX)
        self.wander += -self.wander * DT / WANDER_TIME + WANDER * math.sqrt(
            2.0 * DT / WANDER_TIME
        ) * float(self.rng.normal())
        self.spit -= self.spit * DT / SPIT_TIME
        if self.rng.random() < SPIT_CHANCE:
            self.spit += float(self.rng.choice((-1.0, 1.0))) * float(self.rng.uniform(*SPIT))
        self.gap += self.burn * DT
        h = DT / SUBSTEPS
        lowered, length = self.lowered(), self.length()
        for _ in range(SUBSTEPS):
            self.supply += (asked_voltage - self.supply) * h / RECTIFIER_LAG
            drop = RESISTANCE * self.current + arc_voltage(self.current, length, lowered)
            self.current = max(self.current + (self.supply - drop) * h / self.choke, 0.0)
        self.steps += 1
        target = self.second if self.steps >= self.step_at else self.first
        self.asked += min(max(target - self.asked, -RAMP * DT), RAMP * DT)
        event = (
            "runaway"
            if self.current > RUNAWAY
            else "extinction"
            if self.current < EXTINCTION
            else None
        )
        return (
            self._obs(),
            0.0,
            event is not None,
            False,
            {"event": event, "task": abs(self.current - self.asked)},
        )

    def _obs(self) -> np.ndarray:
        return np.array([self.current, self.voltage(), self.supply, self.asked])


class Regulator:
    """The rectifier's current regulator: the voltage its model of the arc needs at the
    current asked, plus ``kp e + ki integral(e)``, with e the current asked less the current
    read through a lagging, miscalibrated shunt; the lag, the calibration and the gains are
    drawn per episode."""

    def __init__(self, seed: int) -> None:
        self.rng = np.random.default_rng(seed)
        self.kp = self.ki = self.lag = self.calibration = self.integral = 0.0
        self.read: float | None = None

    def reset(self) -> None:
        self.kp = float(np.exp(self.rng.uniform(*np.log(KP))))
        self.ki = float(np.exp(self.rng.uniform(*np.log(KI))))
        self.lag = float(self.rng.uniform(*SHUNT_LAG))
        self.calibration = 1.0 + float(self.rng.uniform(-CALIBRATION, CALIBRATION))
        self.integral = 0.0
        self.read = None

    def __call__(self, obs: np.ndarray) -> float:
        current, _, _, asked = (float(v) for v in obs)
        seen = current * self.calibration
        self.read = seen if self.read is None else self.read + (seen - self.read) * DT / self.lag
        gap = asked - self.read
        self.integral += gap * DT
        model = RESISTANCE * asked + arc_voltage(asked, GAP_ASSUMED)
        voltage = model + self.kp * gap + self.ki * self.integral
        return min(max(voltage, 0.0), VOLTAGE_MAX)


# What a new user writes (client.shield.config_for): the ranges the observation usually
# takes, the rectifier's voltage in 20 bins, and each failure with the direction of the
# voltage that moves away from it; the second adds where each failure lies.
SPACES = Spaces(
    observation_space=Box(
        low=np.array([EXTINCTION, 45.0, 45.0, ASKED[0][0]]),
        high=np.array([RUNAWAY, 75.0, 75.0, ASKED[1][1]]),
        dtype=np.float64,
    ),
    action_space=Box(low=0.0, high=VOLTAGE_MAX, shape=(1,), dtype=np.float64),
)
CONFIG: ShieldConfig = config_for(SPACES, {"runaway": "decrease", "extinction": "increase"})
BOUNDED: ShieldConfig = config_for(
    SPACES,
    {
        "runaway": ("decrease", Bound("x0", above=RUNAWAY)),
        "extinction": ("increase", Bound("x0", below=EXTINCTION)),
    },
)


WORLD = plain_world("arc", Arc, Regulator, CONFIG, MAX_STEPS)
WORLD_BOUNDED = plain_world("arc-bounded", Arc, Regulator, BOUNDED, MAX_STEPS)
