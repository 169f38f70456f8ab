"""Held-out world for #68, second set (a slow failure on either side of one action): a field
watered by drip lines over a clay pan, whose water reaches the roots within hours and fills
the subsoil over days.

A crop grows through a hot, dry fortnight on a loam over a clay pan. Drip lines wet the top
layer of the soil (10 cm), which drains within hours into the root zone (30 cm); the root
zone drains in turn into the subsoil (30 cm) above the clay pan, but only as fast as the
subsoil has room, and the clay pan lets the subsoil drain away only over weeks. The crop
draws its water from the root zone, as much as the day's evaporative demand asks (a sine
over 6:00-18:00, 5-9 mm a day, less under clouds), and less once the root zone dries below
0.22. Now and then a storm (about one a week) rains 2-10 mm/h for 2-8 hours. The action is
the drip lines' rate, in [0, 3] mm/h. Too much water, night after night, fills the subsoil;
once it is full the root zone can no longer drain, and the next heavy watering or storm,
days after the water that filled it, drowns the roots: ``waterlogged``, the root zone's water
content above 0.38 (less than 7% of its volume left to air; fought by less water). Too little
lets the crop draw the root zone down to ``wilting``, below 0.17 (fought by more water).
Watering at the full rate waterlogs the field only 15-38 hours later; no watering wilts
the crop after 1.3-12.5 days (in three episodes of four within the 300 steps; storms save
the rest), and a storm on a field already wet waterlogs it now and then whatever is done
(under 2% of episodes).

The soil is three buckets (in mm of water, with contents as fractions of each layer's
volume): a layer above field capacity (0.30) drains into the one below in proportion to its
excess (3 h for the top layer, 12 h for the root zone) times the room left below; the
subsoil drains through the clay pan in 400 h; the top layer evaporates up to 30% of the
demand while it is wet, and water beyond saturation (0.45) runs off. The crop transpires the
demand in full above 0.22 and less, linearly, down to nothing at 0.08 (after the
water-stress function of R. A. Feddes et al. 1978 and the bucket models of FAO-56).

The controller is a weather-based irrigation controller with a soil-probe bypass, the usual
kind: each night from 22:00 it waters, over 6 hours, what it estimates the crop used that
day, the evaporative demand it measured times a crop coefficient set by hand (drawn per
episode, log-uniform in 0.3-4.5, 1 being right), unless its soil probe reads wetter than
0.30 at 22:00. The probe is buried at a depth drawn per episode (its reading mixes 0-60% of
the top layer into the root zone's) and is off by a calibration error drawn per episode
(+-0.05). It never sees the subsoil or the storms coming. Time step 1 h; an episode runs
from 6:00 for at most 300 steps (12.5 days), ending at the first failure. The shield
observes ``[root zone, top layer, subsoil, demand]``: three water contents (fractions) and
the evaporative demand in mm/h. The controller's task figure (``info["task"]``, per step) is
the absolute gap between the root zone's water content and 0.25, the grower's target. Held
out: not used to choose any default (bench/heldout2/README.md).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from gymnasium.spaces import Box

from app.core import Bound, ShieldConfig
from bench.worlds.harness import Spaces, World
from client.shield.spaces import config_for

DT = 1.0  # [h] a step
SUBSTEPS = 4  # Euler steps of the water per step
START = 6.0  # [h] the clock at reset
MAX_STEPS = 300  # 12.5 days
TOP = 100.0  # [mm] the top layer's depth
ROOT = 300.0  # [mm] the root zone's depth, below the top layer
SUB = 300.0  # [mm] the subsoil's depth, above the clay pan
SATURATED = 0.45  # the soil's water content when every pore is full [1]
FIELD_CAPACITY = 0.30  # the water content a layer drains down to [1]
DRY = 0.08  # the top layer's water content when it no longer evaporates [1]
STRESS_FROM = 0.22  # the root zone below which the crop transpires less [1]
STRESS_TO = 0.08  # the root zone at which it stops [1]
TAU_TOP = 3.0  # [h] the top layer drains into the root zone
TAU_ROOT = 12.0  # [h] the root zone drains into the subsoil
TAU_SUB = 400.0  # [h] the subsoil drains through the clay pan and the tile drains
EVAPORATION = 0.3  # the share of the demand the bare top layer evaporates, wet [1]
VALVE_MAX = 3.0  # [mm/h] the drip lines' full rate
WATERLOGGED = 0.38  # the root zone's water content above which the roots suffocate [1]
WILTING = 0.17  # the root zone's water content below which the crop wilts [1]
TARGET = 0.25  # the root zone's water content the grower aims at [1]
STORM_CHANCE = 0.006  # [1/h] a storm starts in an hour
STORM_HOURS = (2, 9)  # [h] how long a storm rains
STORM_RATE = (2.0, 10.0)  # [mm/h]
WATER_FROM = 22.0  # [h] the clock at which the controller starts a night's watering
WATER_HOURS = 6.0  # [h] how long it waters
SKIP = 0.30  # the probe's reading above which it skips a night [1]
COEFFICIENT = (0.3, 4.5)  # the crop coefficient set by hand, log-uniform per episode; 1 right
SHARE = (0.0, 0.6)  # the top layer's share of the probe's reading, per episode
OFFSET = (-0.05, 0.05)  # the probe's calibration error, per episode [1]


class Field:
    """The environment: reset/step like Gymnasium, with ``info["event"]`` and
    ``info["task"]``."""

    def __init__(self) -> None:
        self.rng = np.random.default_rng(0)
        self.hour = START
        self.top = self.root = self.sub = 0.0  # [mm] of water in each layer
        self.daily = self.cloud = self.rain = 0.0
        self.storm_left = 0

    def reset(self, seed: int | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        self.rng = np.random.default_rng(seed)
        self.hour = START
        self.daily = float(self.rng.uniform(5.0, 9.0))  # [mm/day] the clear sky's demand
        self.cloud = 1.0
        self.rain, self.storm_left = 0.0, 0
        self.root = ROOT * float(self.rng.uniform(0.20, 0.30))
        self.top = TOP * float(self.rng.uniform(0.15, 0.30))
        self.sub = SUB * float(self.rng.uniform(FIELD_CAPACITY, 0.40))
        return self._obs(), {"event": None, "task": abs(self.root / ROOT - TARGET)}

    def demand(self) -> float:
        """The evaporative demand now [mm/h]: the day's, spread over 6:00-18:00 as a sine,
        less under clouds and rain."""
        daylight = math.sin(math.pi * (self.hour % 24.0 - 6.0) / 12.0)
        shade = 0.3 if self.rain > 0.0 else self.cloud
        return max(0.0, daylight) * self.daily * math.pi / 24.0 * shade

    def _weather(self) -> None:
        self.cloud = min(max(self.cloud + float(self.rng.normal(0.0, 0.05)), 0.4), 1.0)
        if self.storm_left > 0:
            self.storm_left -= 1
            if self.storm_left == 0:
                self.rain = 0.0
        elif self.rng.random() < STORM_CHANCE:
            self.storm_left = int(self.rng.integers(*STORM_HOURS))
            self.rain = float(self.rng.uniform(*STORM_RATE))

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        valve = min(max(float(np.asarray(action).reshape(-1)[0]), 0.0), VALVE_MAX)
        demand = self.demand()
        h = DT / SUBSTEPS
        for _ in range(SUBSTEPS):
            top, root, sub = self.top / TOP, self.root / ROOT, self.sub / SUB  # contents [1]
            evaporation = (
                EVAPORATION * demand * min(max((top - DRY) / (FIELD_CAPACITY - DRY), 0.0), 1.0)
            )
            stress = min(max((root - STRESS_TO) / (STRESS_FROM - STRESS_TO), 0.0), 1.0)
            transpiration = demand * stress
            room_root = max(SATURATED - root, 0.0) / (SATURATED - FIELD_CAPACITY)
            room_sub = max(SATURATED - sub, 0.0) / (SATURATED - FIELD_CAPACITY)
            # water drains from a layer above field capacity, as fast as the layer below
            # has room for it; the subsoil's room runs out first, over the clay pan
            down_top = max(self.top - FIELD_CAPACITY * TOP, 0.0) / TAU_TOP * min(room_root, 1.0)
            down_root = max(self.root - FIELD_CAPACITY * ROOT, 0.0) / TAU_ROOT * min(room_sub, 1.0)
            out_sub = max(self.sub - FIELD_CAPACITY * SUB, 0.0) / TAU_SUB
            self.top += (valve + self.rain - evaporation - down_top) * h
            self.top = min(self.top, SATURATED * TOP)  # more runs off
            self.root += (down_top - transpiration - down_root) * h
            self.sub += (down_root - out_sub) * h
        self.hour += DT
        self._weather()
        root = self.root / ROOT
        event = "waterlogged" if root > WATERLOGGED else "wilting" if root < WILTING else None
        return (
            self._obs(),
            0.0,
            event is not None,
            False,
            {"event": event, "task": abs(root - TARGET)},
        )

    def _obs(self) -> np.ndarray:
        return np.array([self.root / ROOT, self.top / TOP, self.sub / SUB, self.demand()])


class Irrigator:
    """Each night from 22:00 waters, over 6 hours, what it estimates the crop used that day:
    a crop coefficient set by hand (drawn per episode) times the evaporative demand it
    measured, unless its soil probe (which reads a drawn share of the top layer, and is off
    by a drawn error) reads wetter than ``SKIP`` at 22:00."""

    def __init__(self, seed: int) -> None:
        self.rng = np.random.default_rng(seed)
        self.coefficient = self.share = self.offset = 0.0
        self.hour = START
        self.used = self.tonight = 0.0

    def reset(self) -> None:
        self.coefficient = float(np.exp(self.rng.uniform(*np.log(COEFFICIENT))))
        self.share = float(self.rng.uniform(*SHARE))
        self.offset = float(self.rng.uniform(*OFFSET))
        self.hour = START
        self.used = self.tonight = 0.0

    def __call__(self, obs: np.ndarray) -> float:
        root, top, _, demand = (float(v) for v in obs)
        clock = self.hour % 24.0
        self.hour += DT
        self.used += demand * DT
        if clock == WATER_FROM:  # tonight's water: what the crop used today, by its estimate
            read = self.share * top + (1.0 - self.share) * root + self.offset
            self.tonight = 0.0 if read > SKIP else self.coefficient * self.used
            self.used = 0.0
        watering = clock >= WATER_FROM or clock < (WATER_FROM + WATER_HOURS) % 24.0
        return min(self.tonight / WATER_HOURS, VALVE_MAX) if watering else 0.0


# What a new user writes (client.shield.config_for): the ranges the observation usually
# takes, the drip lines' range in 20 bins, and each failure with the direction of watering
# that moves away from it; the second adds where each failure lies.
SPACES = Spaces(
    observation_space=Box(
        low=np.array([0.1, 0.05, 0.25, 0.0]),
        high=np.array([0.45, 0.45, 0.45, 1.2]),
        dtype=np.float64,
    ),
    action_space=Box(low=0.0, high=VALVE_MAX, shape=(1,), dtype=np.float64),
)
CONFIG: ShieldConfig = config_for(SPACES, {"waterlogged": "decrease", "wilting": "increase"})
BOUNDED: ShieldConfig = config_for(
    SPACES,
    {
        "waterlogged": ("decrease", Bound("x0", above=WATERLOGGED)),
        "wilting": ("increase", Bound("x0", below=WILTING)),
    },
)


def _world(name: str, config: ShieldConfig) -> World:
    return World(
        name=name,
        make=lambda seed: Field(),
        controller=Irrigator,
        config=config,
        event=lambda obs, info: info["event"],
        shield_observation=lambda obs: [float(v) for v in obs],
        max_steps=MAX_STEPS,
    )


WORLD = _world("field", CONFIG)
WORLD_BOUNDED = _world("field-bounded", BOUNDED)
