"""Held-out world for #68 (a slow failure on either side of one action): a greenhouse heated
through a loop of water pipes with thermal mass.

A greenhouse is heated through a winter night by a boiler that warms a loop of heating pipes.
The loop's water is a lagged compartment (time constant 1.5 h) that goes on heating the air
long after the boiler is turned down, and the soil stores heat for hours more (8 h). Outside
it is coldest at 3:00; from 7:00 the sun, behind drifting clouds, heats the air as well. The
action is the boiler's power, in [0, 10] (tenths of its rating). Too much of it through the
night fills the pipes and the soil with heat, and once the sun adds its share the next
morning, hours after the heat was given, the air overheats: ``overheat``, above 29 degC
(fought by less power). Too little lets the air cool to ``chill``, below 9 degC, in the
coldest hours (fought by more power). On any night, a boiler turned to full power overheats
the house only 1-3 hours later, and one turned off chills it within 0.5-6 hours.

The controller is a weather-compensated heating curve, the usual boiler control: power in
proportion to how far the outside lies below the 16 degC set point, times a curve gain set by
hand and drawn per episode (log-uniform in 0.25-3, 1 being right for a closed night), plus a
weak correction on the air temperature, read through a thermometer that lags 40 min behind
it. It never sees the sun, the pipes or the soil, so it corrects late and little.

Time step 5 min; an episode runs from 18:00 to 17:00 the next day (at most 276 steps), ending
at the first failure. The shield observes ``[air, pipes, outside, sun]``: degC, degC, degC and
the fraction of full sun. The controller's task figure (``info["task"]``, per step) is the
absolute gap between the air and the set point, in K. Held out: not used to choose any
default (bench/heldout/README.md).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from gymnasium.spaces import Box

from app.core import Bound, ShieldConfig
from bench.worlds.harness import Spaces, World
from client.shield.spaces import config_for

DT = 1.0 / 12.0  # [h] a step of 5 min
SUBSTEPS = 6  # Euler steps of the physics per step: the air is fast
START = 18.0  # [h] the clock at reset
MAX_STEPS = 276  # 23 h: to 17:00 the next day
POWER_MAX = 10.0  # the boiler's full power [tenths of its rating]
PIPE_GAIN = 6.0  # [K] the pipes' steady excess over the air per unit of power
TAU_PIPES = 1.5  # [h] the loop's water
TAU_AIR = 0.2  # [h] the air
TAU_SOIL = 8.0  # [h] the soil
SOIL_SHARE = 0.5  # the soil's conductance to the air, per the cover's [1]
SUN_GAIN = 22.0  # [K] the air's steady rise over outside under a full sun
SET_POINT = 16.0  # [degC]
OVERHEAT = 29.0  # [degC]
CHILL = 9.0  # [degC]
SENSOR_LAG = 40.0 / 60.0  # [h] the controller's thermometer
KP = 0.1  # the controller's correction on the air it reads [power per K]
CURVE = (0.25, 3.0)  # the heating curve's gain per episode, log-uniform, 1 being right


class Greenhouse:
    """The environment: reset/step like Gymnasium, with ``info["event"]`` and
    ``info["task"]``."""

    def __init__(self) -> None:
        self.rng = np.random.default_rng(0)
        self.hour = START
        self.air = self.pipes = self.soil = self.outside = self.sun = 0.0
        self.mean_out = self.swing = self.front = self.clear = self.cloud = 0.0

    def reset(self, seed: int | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        self.rng = np.random.default_rng(seed)
        self.hour = START
        self.mean_out = float(self.rng.uniform(-8.0, 6.0))  # [degC] the day's mean
        self.swing = float(self.rng.uniform(3.0, 7.0))  # [K] half the day's range
        self.front = 0.0  # [K] the weather's drift from that
        self.clear = float(self.rng.uniform(0.3, 1.0))  # the sky at its clearest
        self.cloud = 1.0
        self._weather()
        self.air = float(self.rng.uniform(14.0, 18.0))
        self.soil = self.air + float(self.rng.uniform(-2.0, 2.0))
        self.pipes = self.air + float(self.rng.uniform(0.0, 15.0))
        return self._obs(), {"event": None, "task": abs(self.air - SET_POINT)}

    def _weather(self) -> None:
        # outside: coldest at 3:00, warmest at 15:00, plus a drifting front
        self.front += float(self.rng.normal(0.0, 0.15))
        self.outside = (
            self.mean_out
            + self.front
            - self.swing * math.cos(2.0 * math.pi * (self.hour - 3.0) / 24.0)
        )
        self.cloud = min(max(self.cloud + float(self.rng.normal(0.0, 0.08)), 0.3), 1.0)
        daylight = math.sin(math.pi * (self.hour % 24.0 - 7.0) / 12.0)
        self.sun = max(0.0, daylight) * self.clear * self.cloud

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        power = min(max(float(np.asarray(action).reshape(-1)[0]), 0.0), POWER_MAX)
        h = DT / SUBSTEPS
        for _ in range(SUBSTEPS):
            # the pipes: d pipes/dt = (G u - (pipes - air)) / tau_pipes
            to_air = self.pipes - self.air
            self.pipes += (PIPE_GAIN * power - to_air) / TAU_PIPES * h
            # the air: d air/dt = (pipes - air + S sun - (air - out) - s (air - soil)) / tau_air
            gain = (
                to_air
                + SUN_GAIN * self.sun
                - (self.air - self.outside)
                - SOIL_SHARE * (self.air - self.soil)
            )
            self.air += gain / TAU_AIR * h
            # the soil: d soil/dt = (air - soil) / tau_soil
            self.soil += (self.air - self.soil) / TAU_SOIL * h
        self.hour += DT
        self._weather()
        event = "overheat" if self.air > OVERHEAT else "chill" if self.air < CHILL else None
        return (
            self._obs(),
            0.0,
            event is not None,
            False,
            {"event": event, "task": abs(self.air - SET_POINT)},
        )

    def _obs(self) -> np.ndarray:
        return np.array([self.air, self.pipes, self.outside, self.sun])


class HeatingCurve:
    """Power ``c (16 - outside) / 6 + 0.1 (16 - air read)``, in [0, 10]: a heating curve
    whose gain c is drawn per episode, and a weak correction on a thermometer that lags
    ``SENSOR_LAG`` behind the air."""

    def __init__(self, seed: int) -> None:
        self.rng = np.random.default_rng(seed)
        self.curve = 1.0
        self.read: float | None = None

    def reset(self) -> None:
        self.curve = float(np.exp(self.rng.uniform(*np.log(CURVE))))
        self.read = None

    def __call__(self, obs: np.ndarray) -> float:
        air, _, outside, _ = (float(v) for v in obs)
        # the thermometer: d read/dt = (air - read) / lag
        self.read = air if self.read is None else self.read + (air - self.read) * DT / SENSOR_LAG
        power = self.curve * (SET_POINT - outside) / PIPE_GAIN + KP * (SET_POINT - self.read)
        return min(max(power, 0.0), POWER_MAX)


# What a new user writes (client.shield.config_for): the ranges the observation usually
# takes, the boiler's range in 20 bins, and each failure with the direction of power that
# moves away from it; the second adds where each failure lies.
SPACES = Spaces(
    observation_space=Box(
        low=np.array([-5.0, -5.0, -20.0, 0.0]),
        high=np.array([40.0, 90.0, 20.0, 1.0]),
        dtype=np.float64,
    ),
    action_space=Box(low=0.0, high=POWER_MAX, shape=(1,), dtype=np.float64),
)
CONFIG: ShieldConfig = config_for(SPACES, {"overheat": "decrease", "chill": "increase"})
BOUNDED: ShieldConfig = config_for(
    SPACES,
    {
        "overheat": ("decrease", Bound("x0", above=OVERHEAT)),
        "chill": ("increase", Bound("x0", below=CHILL)),
    },
)


def _world(name: str, config: ShieldConfig) -> World:
    return World(
        name=name,
        make=lambda seed: Greenhouse(),
        controller=HeatingCurve,
        config=config,
        event=lambda obs, info: info["event"],
        shield_observation=lambda obs: [float(v) for v in obs],
        max_steps=MAX_STEPS,
    )


WORLD = _world("greenhouse", CONFIG)
WORLD_BOUNDED = _world("greenhouse-bounded", BOUNDED)
