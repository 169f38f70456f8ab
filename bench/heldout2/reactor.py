"""Held-out world for #68, second set (a runaway and an extinction on either side of an
unstable operating point): an exothermic stirred-tank reactor held at its middle steady state
by the flow of cooling water through its jacket.

A liquid feed flows through a stirred tank of 1 m^3 (a residence time of 10 min), where it
reacts, A -> B, first order, and gives off heat; the reaction's rate grows steeply with the
temperature (Arrhenius). Cooling water flows through a jacket of 200 L around the tank. The
reactor is run at its middle steady state (near 350 K, half of A converted), the one that
makes most product while the product keeps: a little hotter, the reaction speeds up and gives
off more heat than the jacket takes away, and it climbs on towards the hot steady state; a
little cooler, it slows, gives off less, and cools on towards the cold one, where hardly
anything reacts. Left at the coolant flow that holds it, a reactor 1 K off its operating point
leaves it within 4-25 min (typically 6-8 min); with no coolant it runs away within 2.5 min,
with all of it it dies down within 1.5 min. The action is the coolant flow asked of the
valve, in [0, 1000] L/min (125 L/min holds 350 K). Failures: ``runaway``, the reactor
above 360 K (where the product starts to decompose and the jacket can no longer catch it;
fought by more coolant, a higher action), and ``quench``, below 343 K (the reaction dying
down, its conversion under 30%: the product is off specification; fought by less coolant,
lower). The feed's concentration and temperature and the cooling water's inlet temperature
wander.

The model, in mol/L, K and minutes (the exothermic CSTR of C. van Heerden 1953 and
A. Uppal, W. H. Ray and A. B. Poore 1974, with a jacket of its own): concentration dC/dt =
(q/V)(C_f - C) - k(T) C; temperature dT/dt = (q/V)(T_f - T) + (H / rho c) k(T) C -
UA (T - T_j) / (rho c V); jacket dT_j/dt = (F / V_j)(T_ci - T_j) + UA (T - T_j) /
(rho_w c_w V_j), with k(T) = k_350 exp(E/R (1/350 - 1/T)), F the coolant flow, an adiabatic
rise of 100 K and the wall's conductance UA twice the feed's heat capacity flow.

The controller is the reactor's temperature regulator: the coolant flow that holds 350 K,
plus a correction in proportion to the gap between the temperature it reads and the set
point and to that gap's integral (no anti-windup). It reads the temperature in a thermowell
that lags 0.2-1 min behind the liquid (drawn per episode); its gains are drawn per episode
(log-uniform, 25-100 L/min per K and 1-30 L/min per K min): a loop now well tuned, now too
timid to catch the instability, now with so much integral that it overshoots one way and then
the other; and its coolant valve sticks: it moves only once the flow asked of it is more than
a band (drawn per episode, 0-30 L/min) from where it stands, and then jumps there, so the loop
hunts. The operator moves the set point every 8-20 min to a new target in 347-353 K, at
0.5 K/min. Time step 10 s; at most 300 steps (50 min), ending at the first failure. The shield
observes ``[temperature, jacket temperature, concentration of A, set point]``: K, K, mol/L and
K. The controller's task figure (``info["task"]``, per step) is the absolute gap between the
reactor's temperature and the set point, in K. Held out: not used to choose any default
(bench/heldout2/README.md).
"""

import math
from typing import Any

import numpy as np
from gymnasium.spaces import Box

from app.core import Bound, ShieldConfig
from bench.worlds.harness import Spaces, World
from client.shield.spaces import config_for

DT = 10.0 / 60.0  # [min] a step of 10 s
SUBSTEPS = 5  # Euler steps of the physics per step
MAX_STEPS = 300  # 50 min
VOLUME = 1000.0  # [L] V, the tank
FEED_FLOW = 100.0  # [L/min] q
FEED_CONC = 2.0  # [mol/L] C_f, the design feed
FEED_TEMP = 350.0  # [K] T_f, the design feed
RATE_AT_350 = 0.1  # [1/min] k at 350 K
ACTIVATION = 15000.0  # [K] E / R
HEAT = 2.1e5  # [J/mol] H, the heat given off per mol reacted
RHO_C = 4200.0  # [J/(L K)] rho c, the reacting liquid's heat capacity per litre
UA = 8.4e5  # [J/(min K)] the jacket wall's conductance
JACKET = 200.0  # [L] V_j
WATER_RHO_C = 4184.0  # [J/(L K)] rho_w c_w
COOLANT_IN = 285.0  # [K] T_ci, the design inlet temperature
FLOW_MAX = 1000.0  # [L/min] the coolant valve wide open
JACKET_HELD = 325.0  # [K] the jacket that holds 350 K on the design feed
HELD = UA * (350.0 - JACKET_HELD) / (WATER_RHO_C * (JACKET_HELD - COOLANT_IN))  # [L/min] 125
RUNAWAY = 360.0  # [K]
QUENCH = 343.0  # [K]
SET_POINTS = (347.0, 353.0)  # [K] the range of the set point
SET_EVERY = (48, 121)  # [steps] how long each target holds: 8-20 min
SET_RAMP = 0.5  # [K/min] how fast the operator moves the set point to a new target
KP = (25.0, 100.0)  # [L/min per K] the regulator's proportional gain, log-uniform per episode
KI = (1.0, 30.0)  # [L/min per K min] its integral gain, log-uniform per episode
LAG = (0.2, 1.0)  # [min] its thermowell's lag, per episode
BAND = (0.0, 30.0)  # [L/min] its valve's dead band (stiction), per episode


def rate(temperature: float) -> float:
    """The reaction's rate constant k(T) [1/min], Arrhenius."""
    return RATE_AT_350 * math.exp(ACTIVATION * (1.0 / 350.0 - 1.0 / temperature))


class Reactor:
    """The environment: reset/step like Gymnasium, with ``info["event"]`` and
    ``info["task"]``."""

    def __init__(self) -> None:
        self.rng = np.random.default_rng(0)
        self.conc = self.temp = self.jacket = self.set_point = self.target = 0.0
        self.feed_conc = self.feed_temp = self.coolant_in = 0.0
        self.set_left = 0

    def reset(self, seed: int | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        self.rng = np.random.default_rng(seed)
        self.set_point = self.target = float(self.rng.uniform(*SET_POINTS))
        self.set_left = int(self.rng.integers(*SET_EVERY))
        self.feed_conc = FEED_CONC * float(np.exp(self.rng.normal(0.0, 0.02)))
        self.feed_temp = FEED_TEMP + float(self.rng.normal(0.0, 1.0))
        self.coolant_in = COOLANT_IN + float(self.rng.normal(0.0, 1.0))
        self.temp = self.set_point + float(self.rng.uniform(-0.5, 0.5))
        self.conc = FEED_FLOW * self.feed_conc / (FEED_FLOW + VOLUME * rate(self.temp))
        self.jacket = JACKET_HELD + float(self.rng.uniform(-1.0, 1.0))
        return self._obs(), {"event": None, "task": abs(self.temp - self.set_point)}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        coolant = min(max(float(np.asarray(action).reshape(-1)[0]), 0.0), FLOW_MAX)
        h = DT / SUBSTEPS
        for _ in range(SUBSTEPS):
            reacted = rate(self.temp) * self.conc  # [mol/(L min)]
            through_wall = UA * (self.temp - self.jacket)  # [J/min]
            self.conc += (FEED_FLOW / VOLUME * (self.feed_conc - self.conc) - reacted) * h
            self.temp += (
                FEED_FLOW / VOLUME * (self.feed_temp - self.temp)
                + HEAT / RHO_C * reacted
                - through_wall / (RHO_C * VOLUME)
            ) * h
            self.jacket += (
                coolant / JACKET * (self.coolant_in - self.jacket)
                + through_wall / (WATER_RHO_C * JACKET)
            ) * h
        # the feed and the cooling water wander about their design values
        self.feed_conc += 0.05 * (FEED_CONC - self.feed_conc) * DT + 0.002 * float(
            self.rng.normal()
        )
        self.feed_temp += 0.05 * (FEED_TEMP - self.feed_temp) * DT + 0.1 * float(self.rng.normal())
        self.coolant_in += 0.05 * (COOLANT_IN - self.coolant_in) * DT + 0.1 * float(
            self.rng.normal()
        )
        self.set_left -= 1
        if self.set_left == 0:
            self.target = float(self.rng.uniform(*SET_POINTS))
            self.set_left = int(self.rng.integers(*SET_EVERY))
        ramp = SET_RAMP * DT
        self.set_point += min(max(self.target - self.set_point, -ramp), ramp)
        event = "runaway" if self.temp > RUNAWAY else "quench" if self.temp < QUENCH else None
        return (
            self._obs(),
            0.0,
            event is not None,
            False,
            {"event": event, "task": abs(self.temp - self.set_point)},
        )

    def _obs(self) -> np.ndarray:
        return np.array([self.temp, self.jacket, self.conc, self.set_point])


class Regulator:
    """Coolant ``HELD + kp e + ki integral(e)``, with e the temperature read in a thermowell
    that lags behind the liquid less the set point, through a valve that moves only once the
    flow asked is more than its band from where it stands; the lag, the gains and the band
    are drawn per episode."""

    def __init__(self, seed: int) -> None:
        self.rng = np.random.default_rng(seed)
        self.kp = self.ki = self.lag = self.band = self.integral = self.valve = 0.0
        self.read: float | None = None

    def reset(self) -> None:
        self.kp = float(np.exp(self.rng.uniform(np.log(KP[0]), np.log(KP[1]))))
        self.ki = float(np.exp(self.rng.uniform(np.log(KI[0]), np.log(KI[1]))))
        self.lag = float(self.rng.uniform(*LAG))
        self.band = float(self.rng.uniform(*BAND))
        self.integral = 0.0
        self.valve = HELD
        self.read = None

    def __call__(self, obs: np.ndarray) -> float:
        temp, _, _, set_point = (float(v) for v in obs)
        # the thermowell: d read/dt = (temp - read) / lag
        self.read = temp if self.read is None else self.read + (temp - self.read) * DT / self.lag
        gap = self.read - set_point
        self.integral += gap * DT
        asked = min(max(HELD + self.kp * gap + self.ki * self.integral, 0.0), FLOW_MAX)
        if abs(asked - self.valve) > self.band:  # the valve sticks, then jumps
            self.valve = asked
        return self.valve


# What a new user writes (client.shield.config_for): the ranges the observation usually
# takes, the coolant's range in 20 bins, and each failure with the direction of coolant that
# moves away from it; the second adds where each failure lies.
SPACES = Spaces(
    observation_space=Box(
        low=np.array([QUENCH, 285.0, 0.5, SET_POINTS[0]]),
        high=np.array([RUNAWAY, 360.0, 1.5, SET_POINTS[1]]),
        dtype=np.float64,
    ),
    action_space=Box(low=0.0, high=FLOW_MAX, shape=(1,), dtype=np.float64),
)
CONFIG: ShieldConfig = config_for(SPACES, {"runaway": "increase", "quench": "decrease"})
BOUNDED: ShieldConfig = config_for(
    SPACES,
    {
        "runaway": ("increase", Bound("x0", above=RUNAWAY)),
        "quench": ("decrease", Bound("x0", below=QUENCH)),
    },
)


def _world(name: str, config: ShieldConfig) -> World:
    return World(
        name=name,
        make=lambda seed: Reactor(),
        controller=Regulator,
        config=config,
        event=lambda obs, info: info["event"],
        shield_observation=lambda obs: [float(v) for v in obs],
        max_steps=MAX_STEPS,
    )


WORLD = _world("reactor", CONFIG)
WORLD_BOUNDED = _world("reactor-bounded", BOUNDED)
