"""Stable-Baselines3 TD3 on CarFollowing-v0, with and without the shield.

The shielded learner stores the action the shield applied (``AppliedActionReplayBuffer``), not
the one it proposed. Prints failures (collisions, falling more than 200 m behind) per 1000
steps of training for both.

    python examples/td3_car_following.py [--steps 20000] [--seed 0]
"""

from __future__ import annotations

import argparse
from collections import Counter
from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3 import TD3
from stable_baselines3.common.noise import NormalActionNoise

from app.core import ReviserConfig, ShieldConfig
from client.shield import ShieldWrapper
from client.shield.sb3 import AppliedActionReplayBuffer, Failures

# The car-following shield, its warm-up counted in steps (the learner's first 1000 are random
# actions, then its episodes are few and long): it learns from the first step, revises after.
STEPS_WARMUP = ShieldConfig(reviser=ReviserConfig(activate_after_episodes=0))
WARMUP_STEPS = 5000


def train(steps: int, seed: int, shielded: bool) -> Counter[str]:
    """Train TD3 for ``steps`` steps; the failures met on the way."""
    env: gym.Env[Any, Any] = gym.make("client.sim:CarFollowing-v0")
    extra: dict[str, Any] = {}
    if shielded:
        env = ShieldWrapper(env, config=STEPS_WARMUP, warmup_steps=WARMUP_STEPS)
        extra["replay_buffer_class"] = AppliedActionReplayBuffer
    noise = NormalActionNoise(mean=np.zeros(1), sigma=np.full(1, 0.2))
    model = TD3("MlpPolicy", env, action_noise=noise, learning_starts=1000, seed=seed,
                **extra)
    failures = Failures()
    model.learn(total_timesteps=steps, callback=failures)
    env.close()
    return failures.failures


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=20_000)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    for shielded in (False, True):
        failures = train(args.steps, args.seed, shielded)
        per = 1000.0 * sum(failures.values()) / args.steps
        print(f"{'shielded' if shielded else 'alone':>8}: {per:.2f} failures per 1000 steps "
              f"{dict(failures)}", flush=True)


if __name__ == "__main__":
    main()
