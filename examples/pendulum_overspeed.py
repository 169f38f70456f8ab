"""Pendulum-v1 with a failure it does not know: spinning faster than 6 rad/s either way.

A controller that pumps energy into the swing (full torque along the angular velocity) spins
the pendulum ever faster. The shield is told of an overspeed by a failure predicate, at any
step (the episode goes on), and learns which torques lead there. Prints the steps spent over
the limit per 1000 steps, with and without the shield, in the episodes after a warm-up in which
the shield learns without revising. Prints progress every 30 s.

    .venv/bin/pip install -e ".[client]"
    .venv/bin/python examples/pendulum_overspeed.py [--episodes 60]
"""

from __future__ import annotations

import argparse
import time
from functools import partial
from typing import Any

import gymnasium as gym
import numpy as np

from app.core import ReviserConfig, ShieldConfig, compiled
from client.shield import ShieldWrapper, config_for

LIMIT = 6.0  # [rad/s]
EVERY_S = 30.0  # [s] between progress lines
say = partial(print, flush=True)


def overspeed(
    observation: Any, reward: float, terminated: bool, truncated: bool, info: dict[str, Any]
) -> str | None:
    """The failure of a step, if any: its name says which way the torque should go."""
    if observation[2] > LIMIT:
        return "overspeed_ccw"  # less torque moves away from it
    if observation[2] < -LIMIT:
        return "overspeed_cw"  # more torque moves away from it
    return None


def run(env: gym.Env[Any, Any], episodes: int, warmup: int, seed: int, arm: str) -> float:
    """Overspeed steps per 1000 steps after ``warmup`` episodes of the energy pump."""
    rng = np.random.default_rng(seed)
    over = steps = 0
    start = time.monotonic()
    next_report = start + EVERY_S
    for episode in range(episodes):
        if time.monotonic() >= next_report:
            next_report = time.monotonic() + EVERY_S
            say(f"  {arm}: {episode}/{episodes} episodes, {time.monotonic() - start:.0f} s")
        observation, _ = env.reset(seed=seed + episode)
        done = False
        while not done:
            push = 2.0 if observation[2] >= 0 else -2.0
            action = np.array([np.clip(push + rng.normal(0.0, 0.5), -2.0, 2.0)], np.float32)
            observation, reward, terminated, truncated, _ = env.step(action)
            done = terminated or truncated
            if episode >= warmup:
                steps += 1
                over += overspeed(observation, float(reward), terminated, truncated, {}) is not None
    return 1000.0 * over / max(steps, 1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=60)
    parser.add_argument("--warmup", type=int, default=20)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    say("loading the shield's compiled core (a first run compiles it: a minute or two)")
    say(f"  ready in {compiled.warm().seconds:.0f} s")
    plain = gym.make("Pendulum-v1")
    revising = ShieldConfig(reviser=ReviserConfig(activate_after_episodes=args.warmup))
    config = config_for(
        plain, {"overspeed_ccw": "decrease", "overspeed_cw": "increase"}, base=revising
    )
    shielded = ShieldWrapper(gym.make("Pendulum-v1"), config=config, failure=overspeed)
    say(
        f"the energy pump for {args.episodes} episodes, alone then shielded (the shield "
        f"revises after episode {args.warmup})"
    )
    alone = run(plain, args.episodes, args.warmup, args.seed, "alone")
    with_shield = run(shielded, args.episodes, args.warmup, args.seed, "shielded")
    say(f"overspeed steps per 1000: alone {alone:.1f}, shielded {with_shield:.1f}")


if __name__ == "__main__":
    main()
