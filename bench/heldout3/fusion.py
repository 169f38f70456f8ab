"""Held-out world for #68, third set (a runaway and an extinction on either side of an
unstable operating point): a burning deuterium-tritium plasma in a tokamak, held at the fusion
power asked by its auxiliary heating.

A tokamak of 830 m^3 (ITER's size) burns a deuterium-tritium plasma at 1e20 ions per m^3 and
about 9 keV. The fusion reactions' alpha particles heat the plasma, and between 8 and 20 keV
their heating grows with the square of the temperature, faster than the plasma loses its
energy: a plasma a little hotter heats itself more and grows hotter still, towards the beta
limit; a little cooler, it heats itself less and cools on until the burn goes out. Auxiliary
heating (beams and microwaves) makes up the rest of the losses; it is the action, the power
asked of the heating systems, in [0, 73] MW (about 35 MW holds the design burn), which they
deliver within 0.5 s. The energy confinement time (drawn per pulse, a factor 0.9-1.1 on its
nominal 3.4 s) wanders by a few per cent over seconds; edge-localised modes (ELMs, about one
every 3 s) throw out 0.5-2% of the plasma's energy at once; fuelling pellets (about one every
4 s) raise the density by 1-4% and cool the plasma as much (its pressure, and so its fusion
power, stays; its bremsstrahlung grows); and the
helium ash of the burn dilutes the fuel (its share grows with the fusion power and is pumped
out over 10-30 s, drawn per pulse). Failures: ``runaway``, the fusion power above 800 MW (the
divertor's heat load, and the beta limit beyond; fought by less heating, a lower action), and
``extinction``, below 250 MW (the burn lost; fought by more heating, higher). Left at the
heating that held it, a burn with 10% more energy runs away within 3-12 s and one with 10%
less goes out within 5-9 s; with no auxiliary heating the burn goes out, and with all of it
runs away, within 2-5 s.

The zero-dimensional power balance (J. Wesson, Tokamaks, 2011, chapter 1): the plasma's
energy W = 3 n T V, dW/dt = P_alpha + P_aux - W / tau_E - P_brems, with P_alpha = n_DT^2 / 4
<sigma v> E_alpha V, <sigma v> = 1.1e-24 T^2 m^3/s (T in keV, Wesson's fit for 10-20 keV),
E_alpha = 3.5 MeV, the fuel's density n_DT = n (1 - 2 f_He), and bremsstrahlung P_brems =
5.35e-37 Z_eff n^2 T^0.5 W/m^3 with Z_eff 1.6; the fusion power is five times P_alpha. The
density relaxes to the fuelling's target (drawn per pulse, 0.95-1.05 e20/m^3) over 3 s
between pellets; the ash's share f_He relaxes over tau_He towards 1% + 3% of the fusion power
over 500 MW.

The controller is the plasma control system's burn controller: the design heating plus a
correction in proportion to the gap between the fusion power asked and the fusion power read,
and to that gap's integral (no anti-windup). It reads the fusion power from neutron cameras
that lag 0.3-1.2 s (drawn per pulse) and are calibrated within +-8% (drawn per pulse); its
gains are drawn per pulse (log-uniform, 0.06-0.5 MW of heating per MW of fusion power, and
0.01-0.2 per MW s): a loop now well tuned, now too timid to catch the instability, now
overshooting. The operator asks a new fusion power every 10-20 s, in 400-600 MW, reached in a
ramp of 20 MW/s. Time step 0.2 s; an episode runs for at most 250 steps (50 s), ending at
the first failure. The shield observes ``[fusion power, temperature, density, fusion power
asked]`` in MW, keV, 1e20/m^3 and MW. The controller's task figure (``info["task"]``, per step)
is the absolute gap between the fusion power and the power asked, in MW. Held out: not used to
choose any default (bench/heldout3/README.md).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from gymnasium.spaces import Box

from app.core import Bound, ShieldConfig
from bench.worlds.harness import Spaces, plain_world
from client.shield.spaces import config_for

DT = 0.2  # [s]
SUBSTEPS = 4  # Euler steps of the plasma per step
MAX_STEPS = 250  # 50 s
VOLUME = 830.0  # [m^3]
ENERGY = 3.0 * 1e20 * 1.602e-16 * VOLUME / 1e6  # [MJ per (1e20/m^3 keV)]: W = ENERGY n T
ALPHA = 0.25 * 1e40 * 1.1e-24 * 3.5e3 * 1.602e-16 * VOLUME / 1e6  # [MW]: P_alpha / (n_DT T)^2
BREMS = 5.35e-37 * 1.6 * 1e40 * VOLUME / 1e6  # [MW]: P_brems / (n^2 T^0.5)
TAU_E = 3.4  # [s] the nominal energy confinement time
CONFINEMENT = (0.9, 1.1)  # the pulse's factor on it
WANDER = 0.03  # the confinement's wander, standard deviation of its share
WANDER_TIME = 3.0  # [s] its correlation time
HEATING_MAX = 73.0  # [MW] the auxiliary heating installed
HEATING_LAG = 0.5  # [s] the heating systems answer
DESIGN_HEATING = 35.0  # [MW] the heating that holds the design burn
ELM_CHANCE = 0.07  # [1/step] an ELM
ELM = (0.005, 0.02)  # the share of the energy it throws out
PELLET_CHANCE = 0.05  # [1/step] a fuelling pellet
PELLET = (0.01, 0.04)  # the share by which it raises the density
DENSITY = (0.95, 1.05)  # [1e20/m^3] the fuelling's target, per pulse
DENSITY_TIME = 3.0  # [s]
ASH_TIME = (10.0, 30.0)  # [s] the helium ash's pumping, per pulse
RUNAWAY = 800.0  # [MW] of fusion power
EXTINCTION = 250.0  # [MW]
ASKED = (400.0, 600.0)  # [MW] the fusion powers the operator asks
ASK_EVERY = (50, 101)  # [steps] how long each holds
RAMP = 20.0  # [MW/s]
CAMERA_LAG = (0.3, 1.2)  # [s] the neutron cameras, per pulse
CALIBRATION = 0.08  # their largest calibration error, per pulse
KP = (0.06, 0.5)  # [MW/MW] log-uniform per pulse
KI = (0.01, 0.2)  # [MW/(MW s)] log-uniform per pulse


def fusion_power(density: float, temperature: float, ash: float) -> float:
    """The fusion power [MW] of a plasma of ``density`` [1e20/m^3], ``temperature`` [keV] and
    helium ash share ``ash``."""
    return 5.0 * ALPHA * (density * (1.0 - 2.0 * ash) * temperature) ** 2


class Plasma:
    """The environment: reset/step like Gymnasium, with ``info["event"]`` and
    ``info["task"]``."""

    def __init__(self) -> None:
        self.rng = np.random.default_rng(0)
        self.energy = self.density = self.ash = self.heating = 0.0
        self.confinement = self.wander = self.target_density = self.ash_time = 0.0
        self.asked = self.target = 0.0
        self.asked_left = 0

    def reset(self, seed: int | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        self.rng = np.random.default_rng(seed)
        self.confinement = TAU_E * float(self.rng.uniform(*CONFINEMENT))
        self.target_density = float(self.rng.uniform(*DENSITY))
        self.ash_time = float(self.rng.uniform(*ASH_TIME))
        self.density = self.target_density
        self.asked = self.target = float(self.rng.uniform(*ASKED))
        self.asked_left = int(self.rng.integers(*ASK_EVERY))
        self.ash = self.ash_share(self.asked)
        temperature = math.sqrt(self.asked / (5.0 * ALPHA)) / (self.density * (1.0 - 2 * self.ash))
        temperature *= 1.0 + float(self.rng.uniform(-0.01, 0.01))
        self.energy = ENERGY * self.density * temperature
        self.wander = 0.0
        self.heating = self.held()
        return self._obs(), {"event": None, "task": abs(self.power() - self.asked)}

    @staticmethod
    def ash_share(power: float) -> float:
        """The helium ash's share at a steady fusion power [MW]."""
        return 0.01 + 0.03 * power / 500.0

    def temperature(self) -> float:
        return self.energy / (ENERGY * self.density)

    def power(self) -> float:
        return fusion_power(self.density, self.temperature(), self.ash)

    def held(self) -> float:
        """The auxiliary heating that holds the plasma's energy where it is now [MW]."""
        loss = self.energy / (self.confinement * (1.0 + self.wander))
        brems = BREMS * self.density**2 * math.sqrt(self.temperature())
        return loss + brems - self.power() / 5.0

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        asked_heating = min(max(float(np.asarray(action).reshape(-1)[0]), 0.0), HEATING_MAX)
        self.wander += -self.wander * DT / WANDER_TIME + WANDER * math.sqrt(
            2.0 * DT / WANDER_TIME
        ) * float(self.rng.normal())
        h = DT / SUBSTEPS
        for _ in range(SUBSTEPS):
            self.heating += (asked_heating - self.heating) * h / HEATING_LAG
            temperature = max(self.temperature(), 0.1)
            alpha = fusion_power(self.density, temperature, self.ash) / 5.0
            loss = self.energy / (self.confinement * (1.0 + self.wander))
            brems = BREMS * self.density**2 * math.sqrt(temperature)
            self.energy += (alpha + self.heating - loss - brems) * h
            self.density += (self.target_density - self.density) * h / DENSITY_TIME
            self.ash += (self.ash_share(5.0 * alpha) - self.ash) * h / self.ash_time
        if self.rng.random() < ELM_CHANCE:
            self.energy *= 1.0 - float(self.rng.uniform(*ELM))
        if self.rng.random() < PELLET_CHANCE:
            self.density *= 1.0 + float(self.rng.uniform(*PELLET))
        self.asked_left -= 1
        if self.asked_left == 0:
            self.target = float(self.rng.uniform(*ASKED))
            self.asked_left = int(self.rng.integers(*ASK_EVERY))
        ramp = RAMP * DT
        self.asked += min(max(self.target - self.asked, -ramp), ramp)
        power = self.power()
        event = "runaway" if power > RUNAWAY else "extinction" if power < EXTINCTION else None
        return (
            self._obs(),
            0.0,
            event is not None,
            False,
            {"event": event, "task": abs(power - self.asked)},
        )

    def _obs(self) -> np.ndarray:
        return np.array([self.power(), self.temperature(), self.density, self.asked])


class BurnController:
    """Heating ``DESIGN + kp e + ki integral(e)``, with e the fusion power asked less the
    fusion power read by lagging, miscalibrated neutron cameras; the lag, the calibration and
    the gains are drawn per pulse."""

    def __init__(self, seed: int) -> None:
        self.rng = np.random.default_rng(seed)
        self.kp = self.ki = self.lag = self.calibration = self.integral = 0.0
        self.read: float | None = None

    def reset(self) -> None:
        self.kp = float(np.exp(self.rng.uniform(*np.log(KP))))
        self.ki = float(np.exp(self.rng.uniform(*np.log(KI))))
        self.lag = float(self.rng.uniform(*CAMERA_LAG))
        self.calibration = 1.0 + float(self.rng.uniform(-CALIBRATION, CALIBRATION))
        self.integral = 0.0
        self.read = None

    def __call__(self, obs: np.ndarray) -> float:
        power, _, _, asked = (float(v) for v in obs)
        seen = power * self.calibration
        # the cameras: d read/dt = (seen - read) / lag
        self.read = seen if self.read is None else self.read + (seen - self.read) * DT / self.lag
        gap = asked - self.read
        self.integral += gap * DT
        heating = DESIGN_HEATING + self.kp * gap + self.ki * self.integral
        return min(max(heating, 0.0), HEATING_MAX)


# What a new user writes (client.shield.config_for): the ranges the observation usually
# takes, the heating's range in 20 bins, and each failure with the direction of the heating
# that moves away from it; the second adds where each failure lies.
SPACES = Spaces(
    observation_space=Box(
        low=np.array([EXTINCTION, 6.0, 0.9, ASKED[0]]),
        high=np.array([RUNAWAY, 12.0, 1.15, ASKED[1]]),
        dtype=np.float64,
    ),
    action_space=Box(low=0.0, high=HEATING_MAX, shape=(1,), dtype=np.float64),
)
CONFIG: ShieldConfig = config_for(SPACES, {"runaway": "decrease", "extinction": "increase"})
BOUNDED: ShieldConfig = config_for(
    SPACES,
    {
        "runaway": ("decrease", Bound("x0", above=RUNAWAY)),
        "extinction": ("increase", Bound("x0", below=EXTINCTION)),
    },
)


WORLD = plain_world("fusion", Plasma, BurnController, CONFIG, MAX_STEPS)
WORLD_BOUNDED = plain_world("fusion-bounded", Plasma, BurnController, BOUNDED, MAX_STEPS)
