"""Tuning world for #68 (a slow failure on either side of one action): a blood glucose level
kept by an insulin pump whose dose acts only 1-3 hours later.

A person with type 1 diabetes wears an insulin pump through a day from 6:00. Their liver makes
glucose all the time and, with no insulin, their blood glucose climbs towards 25 mmol/L;
insulin lets the body take glucose up. The pump infuses insulin under the skin, where it
passes two depots (40 min each) before it reaches the blood, and it lowers the glucose through
a remote compartment (insulin action, 45 min behind the blood's insulin): a dose's effect
peaks 1.4 hours after it was given, is still half of that 3 hours after and lasts 4-5 hours.
Three meals (at 7-9, 12-14 and 18-20 h, 30-100 g of carbohydrate each, and on half the days a
snack at 15-17 h) raise the glucose through the gut (two 25-min compartments), and on half
the days an hour or two of exercise in the afternoon makes insulin work 1.3-1.8 times as
well. The person's insulin sensitivity is drawn per episode (log-normal, 12%). The action is
the pump's rate, in [0, 12] U/h. Too much of it, given while a meal is still rising, keeps
acting hours after the meal has gone: ``low`` (hypoglycaemia, below 3 mmol/L; fought by less
insulin). Too little: ``high`` (above 15 mmol/L; fought by more). A constant full rate ends
low after about an hour, no insulin at all ends high after 2-4 hours.

The model, in mmol/L and minutes (after the minimal model of R. N. Bergman et al. 1979, with
subcutaneous and gut delays in the manner of R. Hovorka et al. 2004): depots dq1/dt = u/60 -
q1/tau_s, dq2/dt = (q1 - q2)/tau_s; insulin action dX/dt = (S 60 q2/tau_s - X)/tau_x; gut
dg1/dt = meal - g1/tau_g, dg2/dt = (g1 - g2)/tau_g; glucose dG/dt = EGP - (SG + e X) G +
R g2/tau_g, with S the insulin sensitivity ([1/min] of insulin action per U/h), e the
exercise's factor and R the rise per gram of carbohydrate absorbed.

The controller is a simple pump algorithm with no meal bolus: a basal rate plus a dose in
proportion to how far the glucose it reads lies above 6.5 mmol/L (never a negative rate). It
reads a glucose sensor that lags 15 min behind the blood and is miscalibrated by a factor
drawn per episode (0.85-1.15); its basal rate (0.75-1.15 U/h, 0.95 being right for the mean
person) and its gain (log-uniform in 0.08-1.2 U/h per mmol/L) are drawn per episode too. A
timid gain lets a meal's rise through; a keen one piles doses up under the skin while the
glucose still rises, and they act once the meal has gone; between the two the loop rings,
shutting the pump off after a low-going swing and rebounding high. It never sees the depots,
the gut or the exercise. Time step 5 min; at most 288 steps (24 h), ending at the first
failure.

The shield observes ``[glucose, insulin on board, insulin action, carbohydrate on board]``:
mmol/L, U in the depots, the action as the U/h that would hold it for the mean person, and g
in the gut. The controller's task figure (``info["task"]``, per step) is the absolute gap
between the glucose and 6.5 mmol/L. A tuning world: defaults may be chosen on it
(bench/worlds/tuning.py); calibrated alone to fail in about 40% of episodes (seeds 0-8).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium.spaces import Box

from app.core import Bound, ShieldConfig
from bench.worlds.harness import Spaces, plain_world
from client.shield.spaces import config_for

DT = 5.0  # [min]
SUBSTEPS = 5  # Euler steps of the physics per step
START = 6.0  # [h] the clock at reset
MAX_STEPS = 288  # 24 h
RATE_MAX = 12.0  # [U/h] the pump's highest rate
TAU_DEPOT = 40.0  # [min] each of the two subcutaneous depots
TAU_ACTION = 45.0  # [min] insulin action behind the blood's insulin
TAU_GUT = 25.0  # [min] each of the gut's two compartments
EGP = 0.25  # [mmol/L/min] the liver's glucose production
SG = 0.01  # [1/min] glucose's own uptake, without insulin
SENSITIVITY = 0.03  # [1/min per U/h] insulin action per U/h infused, the mean person
RISE = 0.3  # [mmol/L per g] the glucose a gram of carbohydrate adds once absorbed
TARGET = 6.5  # [mmol/L]
LOW = 3.0  # [mmol/L]
HIGH = 15.0  # [mmol/L]
SENSOR_LAG = 15.0  # [min]
MEALS = ((7.0, 9.0), (12.0, 14.0), (18.0, 20.0))  # [h] the windows of the day's meals


class Dose:
    """The environment: reset/step like Gymnasium, with ``info["event"]`` and
    ``info["task"]``."""

    def __init__(self) -> None:
        self.rng = np.random.default_rng(0)
        self.minute = 0.0
        self.q1 = self.q2 = self.action = self.g1 = self.g2 = self.glucose = 0.0
        self.sensitivity = 0.0
        self.meals: list[tuple[float, float]] = []  # (minute, g)
        self.exercise = (0.0, 0.0, 1.0)  # (from minute, to minute, factor)

    def reset(self, seed: int | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        self.rng = np.random.default_rng(seed)
        self.minute = START * 60.0
        self.sensitivity = SENSITIVITY * float(np.exp(self.rng.normal(0.0, 0.12)))
        self.meals = [
            (float(self.rng.uniform(a, b)) * 60.0, float(self.rng.uniform(30.0, 100.0)))
            for a, b in MEALS
        ]
        if self.rng.random() < 0.5:
            self.meals.append(
                (float(self.rng.uniform(15.0, 17.0)) * 60.0, float(self.rng.uniform(10.0, 30.0)))
            )
        if self.rng.random() < 0.5:
            begin = float(self.rng.uniform(14.0, 18.0)) * 60.0
            self.exercise = (
                begin,
                begin + float(self.rng.uniform(60.0, 120.0)),
                float(self.rng.uniform(1.3, 1.8)),
            )
        else:
            self.exercise = (0.0, 0.0, 1.0)
        basal = float(self.rng.uniform(0.7, 1.3))  # [U/h] the night's insulin, still acting
        self.q1 = self.q2 = basal / 60.0 * TAU_DEPOT
        self.action = self.sensitivity * basal
        self.g1 = self.g2 = 0.0
        self.glucose = float(self.rng.uniform(5.0, 9.0))
        return self._obs(), {"event": None, "task": abs(self.glucose - TARGET)}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        rate = min(max(float(np.asarray(action).reshape(-1)[0]), 0.0), RATE_MAX)
        eaten = sum(g for m, g in self.meals if self.minute <= m < self.minute + DT)
        self.g1 += eaten
        begin, end, factor = self.exercise
        boost = factor if begin <= self.minute < end else 1.0
        h = DT / SUBSTEPS
        for _ in range(SUBSTEPS):
            absorbed = self.q2 / TAU_DEPOT  # [U/min]
            self.q1 += (rate / 60.0 - self.q1 / TAU_DEPOT) * h
            self.q2 += (self.q1 - self.q2) / TAU_DEPOT * h
            self.action += (self.sensitivity * 60.0 * absorbed - self.action) / TAU_ACTION * h
            appearing = self.g2 / TAU_GUT  # [g/min]
            self.g1 -= self.g1 / TAU_GUT * h
            self.g2 += (self.g1 - self.g2) / TAU_GUT * h
            self.glucose += (EGP - (SG + boost * self.action) * self.glucose + RISE * appearing) * h
        self.minute += DT
        event = "low" if self.glucose < LOW else "high" if self.glucose > HIGH else None
        return (
            self._obs(),
            0.0,
            event is not None,
            False,
            {"event": event, "task": abs(self.glucose - TARGET)},
        )

    def _obs(self) -> np.ndarray:
        return np.array(
            [self.glucose, self.q1 + self.q2, self.action / SENSITIVITY, self.g1 + self.g2]
        )


class Pump:
    """Rate ``basal + k (read - 6.5)``, in [0, 12] U/h, on a sensor that lags ``SENSOR_LAG``
    behind the glucose and reads it ``scale`` times what it is; basal, k and scale are drawn
    per episode (the imperfection the shield is there to catch)."""

    def __init__(self, seed: int) -> None:
        self.rng = np.random.default_rng(seed)
        self.basal = self.gain = self.scale = 0.0
        self.read: float | None = None

    def reset(self) -> None:
        self.basal = float(self.rng.uniform(0.75, 1.15))  # [U/h]
        self.gain = float(np.exp(self.rng.uniform(np.log(0.08), np.log(1.2))))  # [U/h per mmol/L]
        self.scale = float(self.rng.uniform(0.85, 1.15))
        self.read = None

    def __call__(self, obs: np.ndarray) -> float:
        glucose = float(obs[0]) * self.scale
        # the sensor: d read/dt = (glucose - read) / lag
        self.read = (
            glucose if self.read is None else self.read + (glucose - self.read) * DT / SENSOR_LAG
        )
        rate = self.basal + self.gain * (self.read - TARGET)
        return min(max(rate, 0.0), RATE_MAX)


# What a new user writes (client.shield.config_for): the ranges the observation usually
# takes, the pump's range in 20 bins, and each failure with the direction of the rate that
# moves away from it; the second adds where each failure lies.
SPACES = Spaces(
    observation_space=Box(
        low=np.array([2.0, 0.0, 0.0, 0.0]),
        high=np.array([20.0, 10.0, 5.0, 100.0]),
        dtype=np.float64,
    ),
    action_space=Box(low=0.0, high=RATE_MAX, shape=(1,), dtype=np.float64),
)
CONFIG: ShieldConfig = config_for(SPACES, {"low": "decrease", "high": "increase"})
BOUNDED: ShieldConfig = config_for(
    SPACES,
    {
        "low": ("decrease", Bound("x0", below=LOW)),
        "high": ("increase", Bound("x0", above=HIGH)),
    },
)


WORLD = plain_world("tuning-dose", Dose, Pump, CONFIG, MAX_STEPS)
WORLD_BOUNDED = plain_world("tuning-dose-bounded", Dose, Pump, BOUNDED, MAX_STEPS)
