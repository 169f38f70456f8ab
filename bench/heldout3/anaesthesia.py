"""Held-out world for #68, third set (a slow failure on either side of one action): a patient
kept asleep through an operation by a propofol infusion, whose drug pools in the body's fat
and lowers the blood pressure a quarter of an hour after it lowers the brain's activity.

A patient, induced with a bolus of propofol (2.0-2.8 mg/kg) and an infusion at the scheme's
first rate five minutes before the episode starts, is kept anaesthetised through two hours of
surgery by a propofol infusion, the action, in [0, 300] ug/kg/min (100-150 is usual). The
drug spreads from the blood into the muscles within minutes and into the fat over hours, and
comes back from them: an infusion rate that holds the patient asleep in the first half hour
overdoses them in the second. It acts on the brain, which the bispectral index (BIS, 0-100,
awake near 95) measures, within 2-4 minutes of the blood, and on the blood pressure
(vasodilation and a weaker heart) only 10-20 minutes after it. Surgical stimuli (an incision,
a retractor: from the fifth minute, about one every 20 min, lasting 3-15 min) wake the brain
and raise the blood pressure; now and then (about one an operation) a bleed lowers the
pressure for a while. Failures: ``hypotension``, the mean arterial pressure below 55 mmHg
(the kidneys and the brain under-perfused; fought by less propofol), and ``awareness``, the
BIS above 65 (where the patient may wake and remember the surgery; fought by more). The
infusion at its full rate causes hypotension in three episodes of four, 11-106 minutes later
(5th-95th percentile, median 39); no infusion at all wakes the patient within 3-12 minutes
(the same). About one episode in fifty fails in its first three minutes, where hardly
anything can be done.

The model (per kg of body weight, minutes, ug/mL): the three-compartment pharmacokinetics of
B. Marsh et al. (1991), dA1/dt = R - (k10 + k12 + k13) A1 + k21 A2 + k31 A3, dA2/dt = k12 A1
- k21 A2, dA3/dt = k13 A1 - k31 A3, plasma Cp = A1 / V1, with the patient's own volume and
rate constants drawn per episode (a factor 0.75-1.35 on each); two effect sites, dCe/dt =
ke0 (Cp - Ce) for the brain (ke0 0.15-0.45 /min) and dCm/dt = km (Cp - Cm) for the blood
pressure (km 0.04-0.09 /min, slower, after T. Kazama et al. 1999); BIS = 95 - 87 Ce^2.5 /
(Ce^2.5 + EC50^2.5) plus 10 times the stimulus (0.3-1), EC50 drawn per episode in 2-4 ug/mL;
and the mean arterial pressure MAP = MAP0 (1 - 0.55 Cm^1.5 / (Cm^1.5 + C50^1.5)) plus
20 mmHg times the stimulus, less a bleed (5-15 mmHg, recovering over 20 min), MAP0 drawn in
80-105 mmHg and C50 in 2.5-5 ug/mL.

The controller is the anaesthetist, by the usual manual scheme (10, 8 and then 6 mg/kg/h,
after J. E. Roberts et al. 1988) scaled by how much drug they judge this patient needs (a
factor drawn per episode, log-uniform in 0.6-1.8), who looks at the monitors every few
minutes (every 3-9 min, drawn per episode) and then raises the rate by a share (drawn,
15-50%) when the BIS reads above 50; otherwise lowers it by a quarter when the
blood-pressure cuff, which measures only every 5 min, read below 65 mmHg, or by half the
share when the BIS reads below 35. They do not foresee the drug's pooling, nor the pressure's
lag. Time step 1 min; an episode runs for at most 120 steps (two hours), ending at the first
failure. The shield observes ``[BIS, MAP, Cp, Ce]``: the BIS as the monitor shows it (with
noise, 2.8 standard deviation), the arterial line's mean pressure in mmHg, and the plasma and
brain concentrations the pump predicts from its infusion history with the nominal model
(Marsh's, with a brain of ke0 0.26 /min), in ug/mL, not the patient's own. The controller's
task figure (``info["task"]``, per step) is the absolute gap between the BIS and 45, the middle
of the target band. Held out:
not used to choose any default (bench/heldout3/README.md).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from gymnasium.spaces import Box

from app.core import Bound, ShieldConfig
from bench.worlds.harness import Spaces, plain_world
from client.shield.spaces import config_for

DT = 1.0  # [min] a step
SUBSTEPS = 6  # Euler steps of the drug per step
MAX_STEPS = 120  # two hours
RATE_MAX = 300.0  # [ug/kg/min] the infusion's full rate
# Marsh's model (per kg): the central volume [L/kg] and the rate constants [1/min]
V1 = 0.228
K10, K12, K13, K21, K31 = 0.119, 0.112, 0.0419, 0.055, 0.0033
KE0 = 0.26  # [1/min] the nominal brain effect site
SPREAD = (0.75, 1.35)  # the patient's factor on each volume and rate constant
KE0_RANGE = (0.15, 0.45)  # [1/min] the patient's brain effect site
KM_RANGE = (0.04, 0.09)  # [1/min] the patient's blood-pressure effect site
EC50_RANGE = (2.0, 4.0)  # [ug/mL] the brain concentration of half effect
EC50 = 2.8  # [ug/mL] the nominal one
GAMMA = 2.5  # the brain's Hill coefficient
BIS_AWAKE, BIS_DROP = 95.0, 87.0
MAP0_RANGE = (80.0, 105.0)  # [mmHg] the patient's pressure without propofol
C50_RANGE = (2.5, 5.0)  # [ug/mL] the pressure's concentration of half effect
MAP_DROP = 0.55  # the largest share of the pressure propofol takes away
MAP_GAMMA = 1.5
STIMULUS_BIS, STIMULUS_MAP = 10.0, 20.0  # [1], [mmHg] a full stimulus's rise
STIMULUS_CHANCE = 0.05  # [1/min] a stimulus starts
STIMULUS_MINUTES = (3, 16)
QUIET = 5  # [min] the surgeon's preparation, with no stimulus
BLEED_CHANCE = 0.01  # [1/min] a bleed starts
BLEED = (5.0, 15.0)  # [mmHg] how far it lowers the pressure
BLEED_RECOVERY = 0.05  # [1/min] the fluids given bring it back
BOLUS = (2.0, 2.8)  # [mg/kg] the induction's bolus, INDUCTION min before the start
INDUCTION = 5  # [min]
HYPOTENSION = 55.0  # [mmHg]
AWARENESS = 65.0  # BIS
TARGET = 45.0  # BIS
SCHEME = ((10.0, 10.0 / 0.06), (20.0, 8.0 / 0.06), (1e9, 6.0 / 0.06))  # [min], [ug/kg/min]
JUDGEMENT = (0.6, 1.8)  # the anaesthetist's factor on the scheme, log-uniform per episode
CHECK_EVERY = (3, 10)  # [min] how often they look at the monitors, per episode
STEP_UP = (0.15, 0.5)  # the share by which they change the rate, per episode
CUFF_EVERY = 5  # [min] the blood-pressure cuff's cycle
LOW_CUFF = 65.0  # [mmHg] the cuff reading below which they lower the rate
BIS_HIGH, BIS_LOW = 50.0, 35.0


def _pk(amounts: list[float], rate: float, k: tuple[float, ...], h: float) -> None:
    """One Euler step of the three compartments' amounts [mg/kg] under ``rate``
    [mg/kg/min], with rate constants ``k`` = (k10, k12, k13, k21, k31)."""
    a1, a2, a3 = amounts
    k10, k12, k13, k21, k31 = k
    amounts[0] = a1 + (rate - (k10 + k12 + k13) * a1 + k21 * a2 + k31 * a3) * h
    amounts[1] = a2 + (k12 * a1 - k21 * a2) * h
    amounts[2] = a3 + (k13 * a1 - k31 * a3) * h


class Patient:
    """The environment: reset/step like Gymnasium, with ``info["event"]`` and
    ``info["task"]``."""

    def __init__(self) -> None:
        self.rng = np.random.default_rng(0)
        self.amounts = [0.0, 0.0, 0.0]  # [mg/kg] the patient's compartments
        self.nominal = [0.0, 0.0, 0.0]  # the pump's model of them
        self.k: tuple[float, ...] = (K10, K12, K13, K21, K31)
        self.v1 = V1
        self.ce = self.cm = self.ce_nominal = 0.0
        self.ke0 = self.km = self.ec50 = self.map0 = self.c50 = 0.0
        self.stimulus = self.bleed = self.noise = 0.0
        self.stimulus_left = 0
        self.minute = 0

    def reset(self, seed: int | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        self.rng = np.random.default_rng(seed)
        factor = self.rng.uniform(*SPREAD, size=6)
        self.v1 = V1 * float(factor[0])
        self.k = tuple(
            float(base * f) for base, f in zip((K10, K12, K13, K21, K31), factor[1:], strict=True)
        )
        self.ke0 = float(self.rng.uniform(*KE0_RANGE))
        self.km = float(self.rng.uniform(*KM_RANGE))
        self.ec50 = float(np.exp(self.rng.uniform(*np.log(EC50_RANGE))))
        self.map0 = float(self.rng.uniform(*MAP0_RANGE))
        self.c50 = float(self.rng.uniform(*C50_RANGE))
        bolus = float(self.rng.uniform(*BOLUS))
        self.amounts = [bolus, 0.0, 0.0]
        self.nominal = [bolus, 0.0, 0.0]
        self.ce = self.cm = self.ce_nominal = 0.0
        self.stimulus = self.bleed = self.noise = 0.0
        self.stimulus_left = 0
        self.minute = 0
        for _ in range(INDUCTION):  # the minutes since the bolus, infused at the scheme's start
            self._drug(SCHEME[0][1])
        return self._obs(), {"event": None, "task": abs(self.bis() - TARGET)}

    def _drug(self, rate: float) -> None:
        h = DT / SUBSTEPS
        for _ in range(SUBSTEPS):
            _pk(self.amounts, rate / 1000.0, self.k, h)
            _pk(self.nominal, rate / 1000.0, (K10, K12, K13, K21, K31), h)
            cp = self.amounts[0] / self.v1
            self.ce += self.ke0 * (cp - self.ce) * h
            self.cm += self.km * (cp - self.cm) * h
            self.ce_nominal += KE0 * (self.nominal[0] / V1 - self.ce_nominal) * h

    def bis(self) -> float:
        """The brain's activity, noise-free."""
        ce = math.pow(max(self.ce, 0.0), GAMMA)
        return (
            BIS_AWAKE
            - BIS_DROP * ce / (ce + math.pow(self.ec50, GAMMA))
            + STIMULUS_BIS * self.stimulus
        )

    def pressure(self) -> float:
        """The mean arterial pressure [mmHg]."""
        cm = math.pow(max(self.cm, 0.0), MAP_GAMMA)
        drop = MAP_DROP * cm / (cm + math.pow(self.c50, MAP_GAMMA))
        return self.map0 * (1.0 - drop) + STIMULUS_MAP * self.stimulus - self.bleed

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        rate = min(max(float(np.asarray(action).reshape(-1)[0]), 0.0), RATE_MAX)
        self._drug(rate)
        self.minute += 1
        if self.stimulus_left > 0:
            self.stimulus_left -= 1
            if self.stimulus_left == 0:
                self.stimulus = 0.0
        elif self.minute >= QUIET and self.rng.random() < STIMULUS_CHANCE:
            self.stimulus_left = int(self.rng.integers(*STIMULUS_MINUTES))
            self.stimulus = float(self.rng.uniform(0.3, 1.0))
        self.bleed -= BLEED_RECOVERY * self.bleed * DT
        if self.rng.random() < BLEED_CHANCE:
            self.bleed += float(self.rng.uniform(*BLEED))
        self.noise = 0.7 * self.noise + float(self.rng.normal(0.0, 2.0))
        bis, pressure = self.bis(), self.pressure()
        event = (
            "hypotension" if pressure < HYPOTENSION else "awareness" if bis > AWARENESS else None
        )
        return (
            self._obs(),
            0.0,
            event is not None,
            False,
            {"event": event, "task": abs(bis - TARGET)},
        )

    def _obs(self) -> np.ndarray:
        return np.array(
            [
                self.bis() + self.noise,
                self.pressure(),
                self.nominal[0] / V1,
                self.ce_nominal,
            ]
        )


class Anaesthetist:
    """The manual scheme (10, 8, then 6 mg/kg/h) times a judgement drawn per episode, changed
    at each look at the monitors (every few minutes, drawn): up by a drawn share when the BIS
    reads above 50; else down by a quarter when the cuff (every 5 min) read below 65 mmHg, or
    by half the share when the BIS reads below 35."""

    def __init__(self, seed: int) -> None:
        self.rng = np.random.default_rng(seed)
        self.judgement = self.share = 0.0
        self.every = 0
        self.minute = 0
        self.factor = 1.0
        self.cuff = 100.0

    def reset(self) -> None:
        self.judgement = float(np.exp(self.rng.uniform(*np.log(JUDGEMENT))))
        self.every = int(self.rng.integers(*CHECK_EVERY))
        self.share = float(self.rng.uniform(*STEP_UP))
        self.minute = 0
        self.factor = 1.0
        self.cuff = 100.0

    def __call__(self, obs: np.ndarray) -> float:
        bis, pressure, _, _ = (float(v) for v in obs)
        if self.minute % CUFF_EVERY == 0:
            self.cuff = pressure
        if self.minute > 0 and self.minute % self.every == 0:
            if bis > BIS_HIGH:
                self.factor *= 1.0 + self.share
            elif self.cuff < LOW_CUFF:
                self.factor *= 0.75
            elif bis < BIS_LOW:
                self.factor /= 1.0 + self.share / 2.0
        scheme = next(rate for until, rate in SCHEME if self.minute < until)
        self.minute += 1
        return min(scheme * self.judgement * self.factor, RATE_MAX)


# What a new user writes (client.shield.config_for): the ranges the observation usually
# takes, the infusion's range in 20 bins, and each failure with the direction of the infusion
# that moves away from it; the second adds where each failure lies.
SPACES = Spaces(
    observation_space=Box(
        low=np.array([20.0, HYPOTENSION, 0.0, 0.0]),
        high=np.array([70.0, 110.0, 8.0, 8.0]),
        dtype=np.float64,
    ),
    action_space=Box(low=0.0, high=RATE_MAX, shape=(1,), dtype=np.float64),
)
CONFIG: ShieldConfig = config_for(SPACES, {"hypotension": "decrease", "awareness": "increase"})
BOUNDED: ShieldConfig = config_for(
    SPACES,
    {
        "hypotension": ("decrease", Bound("x1", below=HYPOTENSION)),
        "awareness": ("increase", Bound("x0", above=AWARENESS)),
    },
)


WORLD = plain_world("anaesthesia", Patient, Anaesthetist, CONFIG, MAX_STEPS)
WORLD_BOUNDED = plain_world("anaesthesia-bounded", Patient, Anaesthetist, BOUNDED, MAX_STEPS)
