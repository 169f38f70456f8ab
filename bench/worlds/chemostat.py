"""Tuning world for #68 (a runaway and an extinction on either side of an unstable operating
point): a chemostat growing a cooperative microbe, held at a biomass by its dilution rate.

Fresh medium flows into a stirred culture vessel and culture flows out at the same rate, the
dilution rate D, which washes the microbes out. The microbes grow on the medium's sugar, and
they grow cooperatively (they share the enzymes they secrete, an Allee effect): the denser the
culture, the faster each cell grows. So at any biomass held steady, a little more biomass
grows faster than it is washed out and climbs on, and a little less grows slower and is washed
out ever faster: the operating point is unstable, and at the dilution that would hold the
biomass asked, a culture started within 10% of it blooms or washes out within 5-13 hours
(no dilution blooms it within 1-2 hours, the most washes it out within 1-2 hours). Too dense
a culture takes more oxygen than the aeration gives: ``bloom``, the biomass above 7 g/L
(fought by more dilution); a culture washed out is lost: ``washout``, the biomass below
0.5 g/L (fought by less). The action is the dilution rate, in
[0, 1.5] 1/h. The feed's sugar wanders about 20 g/L (the medium is made up by hand in
batches), and the cells' top growth rate wanders with the vessel's temperature.

Monod growth on the sugar times a Hill term for the cooperation, in g/L and hours: growth
mu = mu_max S/(K_S + S) X^2/(K_A^2 + X^2); biomass dX/dt = (mu - D) X; sugar dS/dt =
D (S_in - S) - mu X / Y, with K_S = 0.5 g/L, K_A = 2 g/L and the yield Y = 0.5 g of cells per
g of sugar (after the chemostat of J. Monod 1950 and A. Novick and L. Szilard 1950, with the
cooperative growth studied in yeast by L. Dai et al., Science 2012).

The controller is the vessel's biomass regulator: the dilution rate its model of the culture
says holds the biomass asked (on the recipe's feed), plus a correction in proportion to the
gap between the biomass it reads and the biomass asked and to its integral. It reads the
biomass with a turbidity probe on a sampling loop that lags 30 min behind the vessel and is
miscalibrated by a factor drawn per episode (0.85-1.15); its model's growth rate is off by a
factor drawn per episode (0.85-1.15), and its gains are drawn per episode (log-uniform, kp in
0.04-1 and ki in 0.02-0.5): now too timid to stop a drift before the culture runs away
either way, now with so much integral action that it overshoots a change of the biomass
asked. It never sees the sugar, the feed or the temperature. The biomass asked changes every
2-4 h between 2 and 4 g/L. Time step 3 min; at most 300 steps (15 h), ending at the first
failure.

The shield observes ``[biomass, sugar, feed sugar, biomass asked]``, all in g/L. The
controller's task figure (``info["task"]``, per step) is the absolute gap between the biomass
and the biomass asked, in g/L. A tuning world: defaults may be chosen on it
(bench/worlds/tuning.py); calibrated alone to fail in about 40% of episodes (seeds 0-8).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium.spaces import Box

from app.core import Bound, ShieldConfig
from bench.worlds.harness import Spaces, plain_world
from client.shield.spaces import config_for

DT = 0.05  # [h] a step of 3 min
SUBSTEPS = 3  # Euler steps of the physics per step
MAX_STEPS = 300  # 15 h
MU_MAX = 1.2  # [1/h] the cells' top growth rate, at the vessel's design temperature
K_SUGAR = 0.5  # [g/L] the sugar at which growth is half its top
K_ALLEE = 2.0  # [g/L] the biomass at which cooperation gives half the top growth
YIELD = 0.5  # [g of cells per g of sugar]
FEED = 20.0  # [g/L] the feed's sugar, as made up
DILUTION_MAX = 1.5  # [1/h]
BLOOM = 7.0  # [g/L]
WASHOUT = 0.5  # [g/L]
ASKED = (2.0, 4.0)  # [g/L] the range of the biomass asked
ASKED_EVERY = (40, 81)  # [steps] how long each biomass asked holds
PROBE_LAG = 30.0 / 60.0  # [h] the sampling loop


def growth(sugar: float, biomass: float, top: float = MU_MAX) -> float:
    """The specific growth rate [1/h]: Monod on the sugar times a Hill term of order 2 on the
    biomass (the cooperation)."""
    return top * sugar / (K_SUGAR + sugar) * biomass**2 / (K_ALLEE**2 + biomass**2)


class Chemostat:
    """The environment: reset/step like Gymnasium, with ``info["event"]`` and
    ``info["task"]``."""

    def __init__(self) -> None:
        self.rng = np.random.default_rng(0)
        self.biomass = self.sugar = self.feed = self.asked = self.top = 0.0
        self.asked_left = 0

    def reset(self, seed: int | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        self.rng = np.random.default_rng(seed)
        self.asked = float(self.rng.uniform(*ASKED))
        self.asked_left = int(self.rng.integers(*ASKED_EVERY))
        self.feed = FEED + float(self.rng.normal(0.0, 1.0))
        self.top = MU_MAX * float(np.exp(self.rng.normal(0.0, 0.05)))
        self.biomass = self.asked * float(self.rng.uniform(0.9, 1.1))
        self.sugar = max(self.feed - self.biomass / YIELD, 0.5)
        return self._obs(), {"event": None, "task": abs(self.biomass - self.asked)}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        dilution = min(max(float(np.asarray(action).reshape(-1)[0]), 0.0), DILUTION_MAX)
        h = DT / SUBSTEPS
        for _ in range(SUBSTEPS):
            mu = growth(self.sugar, self.biomass, self.top)
            uptake = mu * self.biomass / YIELD
            self.biomass += (mu - dilution) * self.biomass * h
            self.sugar = max(self.sugar + (dilution * (self.feed - self.sugar) - uptake) * h, 0.0)
        # the feed's sugar drifts back to the recipe's, batches apart; the temperature wanders
        self.feed += 0.1 * (FEED - self.feed) * DT + 0.3 * float(self.rng.normal())
        self.top += 0.2 * (MU_MAX - self.top) * DT + 0.01 * float(self.rng.normal())
        self.asked_left -= 1
        if self.asked_left == 0:
            self.asked = float(self.rng.uniform(*ASKED))
            self.asked_left = int(self.rng.integers(*ASKED_EVERY))
        event = "bloom" if self.biomass > BLOOM else "washout" if self.biomass < WASHOUT else None
        return (
            self._obs(),
            0.0,
            event is not None,
            False,
            {"event": event, "task": abs(self.biomass - self.asked)},
        )

    def _obs(self) -> np.ndarray:
        return np.array([self.biomass, self.sugar, self.feed, self.asked])


class Regulator:
    """Dilution ``model(asked) + kp e + ki integral(e)``, clipped, with e the biomass read
    less the biomass asked, read on a probe that lags ``PROBE_LAG`` and reads ``scale`` times
    the biomass; the model's growth is off by ``model`` and the gains are drawn per episode
    (the imperfection the shield is there to catch)."""

    def __init__(self, seed: int) -> None:
        self.rng = np.random.default_rng(seed)
        self.kp = self.ki = self.integral = 0.0
        self.scale = self.model = 1.0
        self.read: float | None = None

    def reset(self) -> None:
        self.kp = float(np.exp(self.rng.uniform(np.log(0.04), np.log(1.0))))  # [1/h per g/L]
        self.ki = float(np.exp(self.rng.uniform(np.log(0.02), np.log(0.5))))  # [1/h^2 per g/L]
        self.scale = float(self.rng.uniform(0.85, 1.15))
        self.model = float(self.rng.uniform(0.85, 1.15))
        self.integral = 0.0
        self.read = None

    def __call__(self, obs: np.ndarray) -> float:
        biomass, _, _, asked = (float(v) for v in obs)
        measured = biomass * self.scale
        # the probe: d read/dt = (measured - read) / lag
        self.read = (
            measured if self.read is None else self.read + (measured - self.read) * DT / PROBE_LAG
        )
        gap = self.read - asked
        self.integral += gap * DT
        # what the model says holds the biomass asked, on the recipe's feed
        held = growth(max(FEED - asked / YIELD, 0.0), asked, self.model * MU_MAX)
        return min(max(held + self.kp * gap + self.ki * self.integral, 0.0), DILUTION_MAX)


# What a new user writes (client.shield.config_for): the ranges the observation usually
# takes, the dilution's range in 20 bins, and each failure with the direction of dilution
# that moves away from it; the second adds where each failure lies.
SPACES = Spaces(
    observation_space=Box(
        low=np.array([0.0, 0.0, 15.0, 0.0]), high=np.array([8.0, 20.0, 25.0, 5.0]), dtype=np.float64
    ),
    action_space=Box(low=0.0, high=DILUTION_MAX, shape=(1,), dtype=np.float64),
)
CONFIG: ShieldConfig = config_for(SPACES, {"bloom": "increase", "washout": "decrease"})
BOUNDED: ShieldConfig = config_for(
    SPACES,
    {
        "bloom": ("increase", Bound("x0", above=BLOOM)),
        "washout": ("decrease", Bound("x0", below=WASHOUT)),
    },
)


WORLD = plain_world("tuning-chemostat", Chemostat, Regulator, CONFIG, MAX_STEPS)
WORLD_BOUNDED = plain_world("tuning-chemostat-bounded", Chemostat, Regulator, BOUNDED, MAX_STEPS)
