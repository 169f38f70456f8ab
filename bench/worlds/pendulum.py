"""Held-out world (b): Gymnasium's Pendulum-v1 with an overspeed failure in both directions.

The controller pumps energy into the swing (full torque along the angular velocity, with a
little noise) and so spins the pendulum ever faster; a failure is an angular velocity beyond
+-6 rad/s: ``overspeed_ccw`` (positive, fought by less torque) and ``overspeed_cw`` (negative,
fought by more). The shield observes ``[cos theta, sin theta, theta_dot]``. Episodes last at
most 200 steps. Not used to choose any default.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from app.core import ActionSpec, Bound, Criterion, ObservationSpec, ShieldConfig
from bench.worlds.harness import World

LIMIT = 6.0  # [rad/s]


class EnergyPump:
    """Full torque along the angular velocity, with noise of std 0.5 N m."""

    def __init__(self, seed: int) -> None:
        self.rng = np.random.default_rng(seed)

    def __call__(self, obs: np.ndarray) -> float:
        push = 2.0 if obs[2] >= 0 else -2.0
        return float(np.clip(push + self.rng.normal(0.0, 0.5), -2.0, 2.0))


def overspeed(obs: np.ndarray, info: dict[str, Any]) -> str | None:
    if obs[2] > LIMIT:
        return "overspeed_ccw"
    if obs[2] < -LIMIT:
        return "overspeed_cw"
    return None


CONFIG = ShieldConfig(
    observation=ObservationSpec(
        names=("cos", "sin", "theta_dot"), low=(-1.0, -1.0, -8.0), high=(1.0, 1.0, 8.0), knee=()
    ),
    action=ActionSpec(low=-2.0, high=2.0, step=0.2),
    criteria=(
        Criterion("overspeed_ccw", "decrease", Bound("theta_dot", above=LIMIT)),
        Criterion("overspeed_cw", "increase", Bound("theta_dot", below=-LIMIT)),
    ),
)

WORLD = World(
    name="pendulum-overspeed",
    make=lambda seed: gym.make("Pendulum-v1"),
    controller=EnergyPump,
    config=CONFIG,
    event=overspeed,
    shield_observation=lambda obs: [float(v) for v in obs],
    max_steps=200,
)
