"""SB3 TD3 on CarFollowing-v0 with and without the shield: failures per 1000 training steps.

Each seed trains TD3 twice for the same number of steps, once on the environment alone and
once behind :class:`client.shield.ShieldWrapper` (the default shield, in-process) with the
replay buffer that stores the applied action. Failures are the environment's events
(collisions and falling more than 200 m behind), counted over the whole training. Prints one
line per seed and arm, then the totals and their ratio; ``--out`` writes every count as JSON.

    python bench/sb3_shield.py --seeds 0,1,2 --steps 20000 --out results/sb3/td3.json
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from stable_baselines3 import TD3
from stable_baselines3.common.noise import NormalActionNoise

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from app.core import ReviserConfig, ShieldConfig, compiled
from client.shield import ShieldWrapper  # noqa: E402
from client.shield.sb3 import AppliedActionReplayBuffer, Failures  # noqa: E402

# The car-following shield, its warm-up counted in steps (the learner's first 1000 are random
# actions, then its episodes are few and long): it learns from the first step, revises after.
STEPS_WARMUP = ShieldConfig(reviser=ReviserConfig(activate_after_episodes=0))
WARMUP_STEPS = 5000


def train(seed: int, steps: int, shielded: bool) -> dict[str, Any]:
    """One TD3 training; its failures, episodes, revisions and wall time."""
    torch.manual_seed(seed)
    env: gym.Env[Any, Any] = gym.make("client.sim:CarFollowing-v0")
    extra: dict[str, Any] = {}
    if shielded:
        env = ShieldWrapper(
            env, config=STEPS_WARMUP, warmup_steps=WARMUP_STEPS, stream=f"td3-{seed}"
        )
        extra["replay_buffer_class"] = AppliedActionReplayBuffer
    noise = NormalActionNoise(mean=np.zeros(1), sigma=np.full(1, 0.2))
    model = TD3(
        "MlpPolicy", env, action_noise=noise, learning_starts=1000, seed=seed, device="cpu", **extra
    )
    counter = Failures()
    start = time.perf_counter()
    model.learn(total_timesteps=steps, callback=counter)
    env.close()
    return {
        "seed": seed,
        "shielded": shielded,
        "steps": steps,
        "failures": dict(counter.failures),
        "total": sum(counter.failures.values()),
        "episodes": counter.episodes,
        "revised": counter.revised,
        "wall_s": round(time.perf_counter() - start, 1),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="0,1,2")
    parser.add_argument("--steps", type=int, default=20_000)
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    torch.set_num_threads(1)
    rows = []
    for seed in (int(s) for s in args.seeds.split(",")):
        for shielded in (False, True):
            row = train(seed, args.steps, shielded)
            rows.append(row)
            print(
                f"seed {seed} {'shielded' if shielded else 'alone':>8}: "
                f"{1000 * row['total'] / args.steps:.2f} failures per 1000 steps "
                f"{row['failures']}, {row['episodes']} episodes, {row['revised']} revised, "
                f"{row['wall_s']} s",
                flush=True,
            )
    alone = sum(r["total"] for r in rows if not r["shielded"])
    shielded_total = sum(r["total"] for r in rows if r["shielded"])
    steps = args.steps * len(rows) / 2
    ratio = shielded_total / alone if alone else float("nan")
    print(
        f"total: alone {1000 * alone / steps:.2f}, shielded {1000 * shielded_total / steps:.2f}"
        f" failures per 1000 steps; ratio {ratio:.2f}"
    )
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(
            json.dumps(
                {
                    "machine": platform.processor() or platform.machine(),
                    "core": compiled.version(),
                    "steps": args.steps,
                    "rows": rows,
                    "ratio": ratio,
                },
                indent=1,
            )
        )


if __name__ == "__main__":
    main()
