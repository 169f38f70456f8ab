"""Controllers in physical terms (HighwayEnv's test_stop_before_obstacle idea)."""

from __future__ import annotations

import numpy as np

from client.agents.idm import PRESETS, RandomController
from client.sim import lead
from client.sim.car_following import CarFollowingEnv, StartConfig

SAFE_START = StartConfig(headway=(40.0, 100.0), speed_offset=(-2.0, 0.0))


def outcomes(preset: str, episodes: int = 40) -> list[str | None]:
    idm = PRESETS[preset]
    env = CarFollowingEnv(lead=lead.synthetic(0, hard_braking=True), start=SAFE_START)
    events = []
    for episode in range(episodes):
        obs, info = env.reset(seed=episode)
        for _ in range(800):
            obs, _, terminated, truncated, info = env.step(np.array([idm.act(obs)], np.float32))
            if terminated or truncated:
                break
        events.append(info["event"])
    return events


def test_the_normal_idm_never_collides_behind_a_hard_braking_lead() -> None:
    assert "collision" not in outcomes("normal")


def test_the_aggressive_idm_does() -> None:
    assert outcomes("aggressive").count("collision") > 20


def test_random_controller_is_seeded() -> None:
    obs = np.zeros(4, np.float32)
    a, b = RandomController(3), RandomController(3)
    assert [a.act(obs) for _ in range(5)] == [b.act(obs) for _ in range(5)]
    assert all(-2.0 <= RandomController(4).act(obs) <= 2.0 for _ in range(100))
