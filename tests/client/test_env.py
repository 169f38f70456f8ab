"""The car-following environment: Gymnasium's checker, determinism, and physical behaviour."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from client.sim import lead
from client.sim.car_following import ENV_ID, CarFollowingEnv, RewardConfig, StartConfig


# The checker recommends a [-1, 1] action space; [-2, 2] m/s^2 is the paper's.
@pytest.mark.filterwarnings("ignore:.*symmetric and normalized space")
def test_passes_the_gymnasium_checker() -> None:
    check_env(CarFollowingEnv(lead=lead.synthetic(0)), skip_render_check=True)


def test_is_registered() -> None:
    env = gym.make(ENV_ID, lead=lead.synthetic(0))
    obs, info = env.reset(seed=1)
    assert obs.shape == (4,) and len(info["efsm_observation"]) == 3


def rollout(seed: int, actions: np.ndarray) -> list[tuple[object, ...]]:
    env = CarFollowingEnv(lead=lead.synthetic(5))
    obs, info = env.reset(seed=seed)
    out: list[tuple[object, ...]] = [(obs.tolist(), info["event"])]
    for a in actions:
        obs, reward, terminated, truncated, info = env.step(np.array([a], np.float32))
        out.append((obs.tolist(), reward, terminated, truncated, info["event"]))
        if terminated or truncated:
            break
    return out


def test_same_seed_same_actions_same_rollout() -> None:
    actions = np.random.default_rng(0).uniform(-2, 2, 800)
    assert rollout(3, actions) == rollout(3, actions)
    assert rollout(3, actions) != rollout(4, actions)


def test_point_mass_dynamics() -> None:
    env = CarFollowingEnv(lead=lead.synthetic(1))
    obs, _ = env.reset(seed=0)
    v_ego, headway, v_lead, _ = obs.astype(float)
    obs, _, _, _, _ = env.step(np.array([1.0], np.float32))
    assert obs[0] == pytest.approx(min(v_ego + 0.25, 32), abs=1e-5)
    assert obs[1] == pytest.approx(headway + (v_lead - v_ego) * 0.25, abs=1e-4)
    assert obs[3] == pytest.approx(1.0)


def test_accelerating_into_a_slow_lead_collides() -> None:
    env = CarFollowingEnv(lead=lead.synthetic(2), start=StartConfig(headway=(20.0, 20.0)))
    env.reset(seed=0)
    for _ in range(800):
        *_, terminated, _, info = env.step(np.array([2.0], np.float32))
        if terminated:
            break
    assert info["event"] == "collision"


def test_standing_still_falls_behind() -> None:
    env = CarFollowingEnv(lead=lead.synthetic(3, hard_braking=False))
    env.reset(seed=2)
    events = []
    for _ in range(800):
        *_, terminated, truncated, info = env.step(np.array([-2.0], np.float32))
        events.append(info["event"])
        if terminated or truncated:
            break
    assert events[-1] == "large_distance"
    assert events.count("large_distance") == 1 and "collision" not in events


def test_reward_is_zero_at_the_ideal_point() -> None:
    env = CarFollowingEnv(lead=lead.synthetic(0), reward=RewardConfig())
    env.reset(seed=0)
    env._v_ego, env._v_lead, env._headway, env._a_prev = 10.0, 10.0, 20.0, 0.5
    assert env._reward(0.5) == pytest.approx(0.0)
    assert env._reward(-1.5) < 0.0


def test_a_failure_penalty_lowers_the_reward_of_the_failing_step_only() -> None:
    rewards: dict[float, list[float]] = {}
    for penalty in (0.0, 60.0):
        env = CarFollowingEnv(
            lead=lead.synthetic(2),
            start=StartConfig(headway=(20.0, 20.0)),
            reward=RewardConfig(failure_penalty=penalty),
        )
        env.reset(seed=0)
        rewards[penalty] = []
        while True:
            _, reward, terminated, _, info = env.step(np.array([2.0], np.float32))
            rewards[penalty].append(reward)
            if terminated:
                break
        assert info["event"] == "collision"
    assert rewards[60.0][:-1] == rewards[0.0][:-1]
    assert rewards[60.0][-1] == pytest.approx(rewards[0.0][-1] - 60.0)
