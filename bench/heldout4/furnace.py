"""Held-out world for #68, fourth set (a slow failure on either side of one action): an iron
blast furnace whose hearth is kept hot by the coal injected at its tuyeres, coal whose heat
reaches the hearth only hours later.

A blast furnace makes hot metal (liquid iron) from ore and coke charged at its top, which take
six to eight hours to come down to the hearth; pulverised coal, blown in at the tuyeres with
the hot blast, replaces part of the coke. The action is the coal's injection rate, in
[0, 250] kg per tonne of hot metal (kg/tHM; 130-170 is usual). The coal burns at once in the
raceway, but the heat it saves in the shaft reaches the hearth only as the burden it
pre-heated and pre-reduced comes down: 2-4 h later (drawn per episode), through a chain of
three lags, and the hearth, with its pool of iron and slag, takes 1-2 h (drawn) more to follow.
The coal the burden needs to hold the hot metal at 1500 degC (130-170 kg/tHM, drawn per
episode) wanders with the ore's quality and moisture (10 kg/tHM standard deviation over 4 h),
changes at each new ore blend (about one a shift of 8 h, by up to 25 kg/tHM), and grows with
the blast's moisture (0.9 kg/tHM per g/Nm^3, which wanders by 4 g/Nm^3 over 3 h); now and
then (about one in 12 h) the burden slips, and a mass of cold, unprepared burden drops into
the hearth and chills it by 10-35 degC at once. Failures: ``chill``, the hot metal below
1420 degC (a chilled hearth: the iron and slag stiffen and will not tap, days of recovery;
fought by more coal), and ``overheat``, above 1560 degC (a hot hearth: high-silicon iron, the
burden hangs in the shaft and the hearth's lining wears; fought by less). Full injection
overheats the hearth in all but one episode in 200, 2.5-7 h later (5th-95th percentile, median
4.2 h); no coal at all chills it within 2.5-5 h (median 3.5 h). Held at the rate the last shift
left it, one furnace in eleven fails within the day.

The model (minutes, kg/tHM, degC): the coal's heat passes three stages, dq_i/dt = (q_(i-1) -
q_i) / (delay / 3), q_0 the injection rate; the hot metal follows dT/dt = (T_s - T) /
tau_hearth, towards T_s = 1500 + G (q_3 - need), the gain G drawn per episode in 0.9-1.3 degC
per kg/tHM (about the thermal value of coal as operators quote it), need as above. The hot
metal's silicon is 0.45% + 0.008% per degC above 1500 (and noise, 0.03%), known from the
laboratory 30 min after the cast; the raceway's adiabatic flame temperature falls at once by
2.6 degC per kg/tHM of coal and 5.5 degC per g/Nm^3 of moisture, from 2300 degC.

The controller is the shift's process engineer, who looks at the hot metal's temperature every
1-2.5 h (drawn per episode, at the casts) and changes the injection rate by a drawn amount per
degree between it and their aim (log-uniform, 0.4-3 kg/tHM per degC; their aim drawn in
1490-1510 degC): an engineer now patient, now hasty. They do not foresee that the coal's heat
comes hours late, and go on adding coal to a hearth whose heat is already on its way. Time
step 10 min; an episode runs for at most 144 steps (a day), ending at the first failure. The
shield observes ``[hot metal temperature, silicon, flame temperature, injection rate]``: the
hot metal's temperature as the dip thermocouple reads it (4 degC noise), in degC; its silicon
as the laboratory last reported it, in %; the raceway's flame temperature in degC; and the
coal injection rate in kg/tHM. The controller's task figure (``info["task"]``, per step) is
the absolute gap between the hot metal's temperature and 1500 degC. Held out: not used to
choose any default (bench/heldout4/README.md).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from gymnasium.spaces import Box

from app.core import Bound, ShieldConfig
from bench.worlds.harness import Spaces, plain_world
from client.shield.spaces import config_for

DT = 10.0  # [min] a step
MAX_STEPS = 144  # a day
PCI_MAX = 250.0  # [kg/tHM] the injection's full rate
NEED = (130.0, 170.0)  # [kg/tHM] the coal the burden needs to hold 1500 degC, per episode
NEED_WANDER = 10.0  # [kg/tHM] its wander, standard deviation
NEED_TIME = 240.0  # [min] the wander's correlation time
BLEND_CHANCE = 1.0 / 48.0  # [1/step] a new ore blend (about one a shift of 8 h)
BLEND = 25.0  # [kg/tHM] the largest change of the need it brings
DELAY = (120.0, 240.0)  # [min] the injected coal's heat reaches the hearth, per episode
STAGES = 3  # the chain of lags it passes
HEARTH_TIME = (60.0, 120.0)  # [min] the hearth's thermal time constant, per episode
GAIN = (0.9, 1.3)  # [degC per kg/tHM] the hearth's response to the coal, per episode
HUMIDITY = 15.0  # [g/Nm^3] the blast's mean moisture
HUMIDITY_WANDER = 4.0  # [g/Nm^3] its wander, standard deviation
HUMIDITY_TIME = 180.0  # [min]
HUMIDITY_NEED = 0.9  # [kg/tHM per g/Nm^3] the coal a wetter blast needs
SLIP_CHANCE = 1.0 / 72.0  # [1/step] a burden slip (about one in 12 h)
SLIP = (10.0, 35.0)  # [degC] the cold it brings into the hearth at once
HOT = 1500.0  # [degC] the hot metal with the coal it needs
CHILL = 1420.0  # [degC]
OVERHEAT = 1560.0  # [degC]
TEMPERATURE_NOISE = 4.0  # [degC] the dip thermocouple's
SILICON_LAG = 3  # [steps] the laboratory's
RAFT = 2300.0  # [degC] the raceway's flame temperature with no coal and a mean blast
RAFT_COAL = 2.6  # [degC per kg/tHM]
RAFT_HUMIDITY = 5.5  # [degC per g/Nm^3]
LOOK_EVERY = (6, 16)  # [steps] how often the engineer changes the rate, per episode
K_LOOK = (0.4, 3.0)  # [kg/tHM per degC] their change per degree of gap, per episode
TARGET = (1490.0, 1510.0)  # [degC] their aim, per episode


def silicon(temperature: float) -> float:
    """The hot metal's silicon [%] at ``temperature`` [degC]."""
    return 0.45 + 0.008 * (temperature - HOT)


class Furnace:
    """The environment: reset/step like Gymnasium, with ``info["event"]`` and
    ``info["task"]``."""

    def __init__(self) -> None:
        self.rng = np.random.default_rng(0)
        self.stages = [0.0] * STAGES  # [kg/tHM] the coal's heat on its way down
        self.temperature = self.need = self.wander = self.humidity = 0.0
        self.delay = self.hearth_time = self.gain = self.rate = 0.0
        self.silicon: list[float] = []

    def reset(self, seed: int | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        self.rng = np.random.default_rng(seed)
        self.need = float(self.rng.uniform(*NEED))
        self.delay = float(self.rng.uniform(*DELAY))
        self.hearth_time = float(self.rng.uniform(*HEARTH_TIME))
        self.gain = float(self.rng.uniform(*GAIN))
        self.wander = float(self.rng.normal(0.0, NEED_WANDER))
        self.humidity = HUMIDITY + float(self.rng.normal(0.0, HUMIDITY_WANDER))
        # the furnace as the last shift left it: near balance, the coal in transit its rate
        self.rate = min(max(self.needed() + float(self.rng.normal(0.0, 8.0)), 0.0), PCI_MAX)
        self.stages = [self.rate] * STAGES
        self.temperature = self.settled() + float(self.rng.normal(0.0, 10.0))
        self.silicon = [silicon(self.temperature)] * (SILICON_LAG + 1)
        return self._obs(), {"event": None, "task": abs(self.temperature - HOT)}

    def needed(self) -> float:
        """The coal [kg/tHM] that holds the hearth at 1500 degC now."""
        return self.need + self.wander + HUMIDITY_NEED * (self.humidity - HUMIDITY)

    def settled(self) -> float:
        """The temperature the hearth goes to with the coal now reaching it [degC]."""
        return HOT + self.gain * (self.stages[-1] - self.needed())

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        self.rate = min(max(float(np.asarray(action).reshape(-1)[0]), 0.0), PCI_MAX)
        stage_time = self.delay / STAGES
        inflow = self.rate
        for i in range(STAGES):
            self.stages[i] += (inflow - self.stages[i]) * DT / stage_time
            inflow = self.stages[i]
        self.temperature += (self.settled() - self.temperature) * DT / self.hearth_time
        self.wander += -self.wander * DT / NEED_TIME + NEED_WANDER * math.sqrt(
            2.0 * DT / NEED_TIME
        ) * float(self.rng.normal())
        self.humidity += (HUMIDITY - self.humidity) * DT / HUMIDITY_TIME + HUMIDITY_WANDER * (
            math.sqrt(2.0 * DT / HUMIDITY_TIME)
        ) * float(self.rng.normal())
        if self.rng.random() < BLEND_CHANCE:
            self.need += float(self.rng.uniform(-BLEND, BLEND))
        if self.rng.random() < SLIP_CHANCE:
            self.temperature -= float(self.rng.uniform(*SLIP))
        self.silicon.append(silicon(self.temperature) + float(self.rng.normal(0.0, 0.03)))
        self.silicon.pop(0)
        event = (
            "chill"
            if self.temperature < CHILL
            else "overheat"
            if self.temperature > OVERHEAT
            else None
        )
        return (
            self._obs(),
            0.0,
            event is not None,
            False,
            {"event": event, "task": abs(self.temperature - HOT)},
        )

    def _obs(self) -> np.ndarray:
        return np.array(
            [
                self.temperature + float(self.rng.normal(0.0, TEMPERATURE_NOISE)),
                self.silicon[0],
                RAFT - RAFT_COAL * self.rate - RAFT_HUMIDITY * (self.humidity - HUMIDITY),
                self.rate,
            ]
        )


class Engineer:
    """The shift's process engineer: every few hours (drawn per episode) changes the coal rate
    by a drawn share of the gap between their aim (drawn) and the hot metal's temperature."""

    def __init__(self, seed: int) -> None:
        self.rng = np.random.default_rng(seed)
        self.every = 0
        self.k = self.target = 0.0
        self.rate: float | None = None
        self.minute = 0

    def reset(self) -> None:
        self.every = int(self.rng.integers(*LOOK_EVERY))
        self.k = float(np.exp(self.rng.uniform(*np.log(K_LOOK))))
        self.target = float(self.rng.uniform(*TARGET))
        self.rate = None
        self.minute = 0

    def __call__(self, obs: np.ndarray) -> float:
        temperature, _, _, rate = (float(v) for v in obs)
        if self.rate is None:
            self.rate = rate
        if self.minute > 0 and self.minute % self.every == 0:
            self.rate += self.k * (self.target - temperature)
            self.rate = min(max(self.rate, 0.0), PCI_MAX)
        self.minute += 1
        return self.rate


# What a new user writes (client.shield.config_for): the ranges the observation usually
# takes, the coal rate's range in 20 bins, and each failure with the direction of the coal
# rate that moves away from it; the second adds where each failure lies.
SPACES = Spaces(
    observation_space=Box(
        low=np.array([CHILL, 0.0, 1650.0, 0.0]),
        high=np.array([OVERHEAT, 1.0, 2300.0, PCI_MAX]),
        dtype=np.float64,
    ),
    action_space=Box(low=0.0, high=PCI_MAX, shape=(1,), dtype=np.float64),
)
CONFIG: ShieldConfig = config_for(SPACES, {"chill": "increase", "overheat": "decrease"})
BOUNDED: ShieldConfig = config_for(
    SPACES,
    {
        "chill": ("increase", Bound("x0", below=CHILL)),
        "overheat": ("decrease", Bound("x0", above=OVERHEAT)),
    },
)


WORLD = plain_world("furnace", Furnace, Engineer, CONFIG, MAX_STEPS)
WORLD_BOUNDED = plain_world("furnace-bounded", Furnace, Engineer, BOUNDED, MAX_STEPS)
