"""Stable-Baselines3 TD3 on CarFollowing-v0, with and without the shield.

The shielded learner stores the action the shield applied (``AppliedActionReplayBuffer``), not
the one it proposed. The shield learns from the first step and acts after a warm-up (a quarter
of the run unless ``--warmup`` says otherwise): before that it only watches, and both arms
meet the same failures. Prints progress every 30 s, then failures (collisions, falling more
than 200 m behind) per 1000 steps of training for both. About 4 minutes on a 2-core machine
as written; ``--steps 10000 --warmup 5000`` is the bench's setting (results/sb3/README.md).

    .venv/bin/pip install -e ".[client,sb3]"
    .venv/bin/python examples/td3_car_following.py [--steps 6000] [--warmup 1500] [--seed 0]
"""

from __future__ import annotations

import argparse
import sys
from functools import partial
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from stable_baselines3 import TD3
from stable_baselines3.common.noise import NormalActionNoise

from app.core import compiled
from client.shield import ShieldWrapper
from client.shield.sb3 import AppliedActionReplayBuffer, Failures

RANDOM_STEPS = 1000  # TD3's random actions before it learns
say = partial(print, flush=True)


def train(steps: int, warmup: int, seed: int, shielded: bool) -> Failures:
    """Train TD3 for ``steps`` steps, shielded after ``warmup``; what it met on the way."""
    env: gym.Env[Any, Any] = gym.make("client.sim:CarFollowing-v0")
    extra: dict[str, Any] = {}
    if shielded:
        # the environment's own shield (the car-following defaults), its warm-up counted in
        # steps: TD3's episodes are few and long
        env = ShieldWrapper(env, warmup_steps=warmup)
        extra["replay_buffer_class"] = AppliedActionReplayBuffer
    noise = NormalActionNoise(mean=np.zeros(1), sigma=np.full(1, 0.2))
    model = TD3(
        "MlpPolicy",
        env,
        action_noise=noise,
        learning_starts=RANDOM_STEPS,
        seed=seed,
        device="cpu",
        **extra,
    )
    arm = "shielded" if shielded else "alone"
    failures = Failures(report=lambda line: say(f"  {arm}: {line}"))
    model.learn(total_timesteps=steps, callback=failures)
    env.close()
    return failures


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=6000)
    parser.add_argument(
        "--warmup",
        type=int,
        default=None,
        help="steps in which the shield only watches (default: steps / 4)",
    )
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    warmup = args.steps // 4 if args.warmup is None else args.warmup
    if warmup >= args.steps:
        print(
            f"warning: the shield watches for its warm-up of {warmup} steps and this run has "
            f"{args.steps}: it never acts, and both arms meet the same failures. Give more "
            f"--steps or a shorter --warmup.",
            file=sys.stderr,
            flush=True,
        )
    torch.set_num_threads(1)  # small networks: one thread is as fast and leaves a core free
    say("loading the shield's compiled core (a first run compiles it: a minute or two)")
    say(f"  ready in {compiled.warm().seconds:.0f} s")
    say(
        f"TD3 for {args.steps} steps, alone then shielded (the shield acts after step "
        f"{warmup}; TD3's first {RANDOM_STEPS} actions are random)"
    )
    for shielded in (False, True):
        run = train(args.steps, warmup, args.seed, shielded)
        per = 1000.0 * sum(run.failures.values()) / args.steps
        say(
            f"{'shielded' if shielded else 'alone':>8}: {per:.2f} failures per 1000 steps "
            f"{dict(run.failures)}, {run.revised} actions revised"
        )
        if shielded and run.revised == 0 and warmup < args.steps:
            print(
                f"warning: the shield revised no action after its warm-up of {warmup} steps "
                f"(it had not learned yet where the failures lie), so both arms met the same "
                f"failures. Give more --steps.",
                file=sys.stderr,
                flush=True,
            )


if __name__ == "__main__":
    main()
