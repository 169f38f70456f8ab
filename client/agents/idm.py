"""The Intelligent Driver Model follower, with presets, and a random controller."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

A_LIMIT = 2.0  # [m/s^2] the simulator's bound


@dataclass(frozen=True)
class IDM:
    """``a = a_max [1 - (v / v0)^4 - (s* / s)^2]``, ``s* = s0 + v T + v dv / (2 sqrt(a_max b))``,
    clipped to the simulator's +-2 m/s^2 (Treiber, Hennecke, Helbing 2000)."""

    v0: float = 30.0  # [m/s] desired speed
    time_headway: float = 2.0  # [s] T
    s0: float = 4.0  # [m] standstill gap
    a_max: float = 1.2  # [m/s^2]
    b: float = 1.2  # [m/s^2] comfortable deceleration, below the 2 m/s^2 the car can do

    def act(self, observation: npt.NDArray[np.float32]) -> float:
        """The acceleration for ``[v_ego, headway, v_lead, a_prev]``."""
        v, s, v_lead = float(observation[0]), float(observation[1]), float(observation[2])
        s_star = self.s0 + max(
            0.0, v * self.time_headway + v * (v - v_lead) / (2.0 * math.sqrt(self.a_max * self.b))
        )
        a = self.a_max * (1.0 - (v / self.v0) ** 4 - (s_star / max(s, 0.1)) ** 2)
        return min(max(a, -A_LIMIT), A_LIMIT)


PRESETS = {
    # plans with gentler braking than the car can do: never collides from a feasible start
    "normal": IDM(),
    # short headway and standstill gap, late braking: it crashes behind a hard-braking lead
    "aggressive": IDM(v0=32.0, time_headway=0.4, s0=0.5, a_max=2.0, b=4.0),
    # wants to drive slower than the lead and speeds up gently: it falls more than 200 m behind
    "sluggish": IDM(v0=22.0, a_max=0.8),
}


class RandomController:
    """Uniform random accelerations, from its own seeded generator."""

    def __init__(self, seed: int) -> None:
        self.rng = np.random.default_rng(seed)

    def act(self, observation: npt.NDArray[np.float32]) -> float:
        return float(self.rng.uniform(-A_LIMIT, A_LIMIT))
