"""What one training step of R DDPG learners costs: an update and an action of each.

* R separate learners (:class:`DDPG`, one after the other, as R processes would do it);
* one batched ensemble on the CPU (``--lockstep``);
* the same ensemble on CUDA, its update a captured graph (``--lockstep --device cuda``), where
  a GPU is present.

Every learner first holds 1000 transitions; times are per step of all R learners, the median
over rounds. The ratio is separate learners over the batched path.

    python bench/learner.py --rounds 5
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from client.agents.ddpg import DDPG, DDPGConfig  # noqa: E402
from client.agents.ensemble import DDPGEnsemble  # noqa: E402

CONFIG = DDPGConfig(warmup=64)


def fill(members: list[DDPG]) -> None:
    rng = np.random.default_rng(0)
    for member in members:
        for _ in range(1000):
            obs = rng.uniform(0, 30, 4).astype(np.float32)
            member.remember(obs, 0.0, -1.0, rng.uniform(0, 30, 4).astype(np.float32), False)


def per_step_ms(step: Callable[[], Any], steps: int) -> float:
    for _ in range(10):  # eager updates, graph capture, allocator warm-up
        step()
    start = time.perf_counter()
    for _ in range(steps):
        step()
    return (time.perf_counter() - start) / steps * 1e3


def separate_ms(members: int, steps: int) -> float:
    learners = [DDPG(CONFIG, seed) for seed in range(members)]
    fill(learners)
    obs = np.full(4, 10.0, np.float32)

    def step() -> None:
        for learner in learners:
            learner.update()
            learner.act(obs)

    return per_step_ms(step, steps)


def ensemble_ms(members: int, device: str, steps: int) -> float:
    ensemble = DDPGEnsemble(CONFIG, list(range(members)), device)
    fill(ensemble.members)
    obs = np.full((members, 4), 10.0, np.float32)

    def step() -> None:
        ensemble.update()
        ensemble.act(obs)  # waits for the update: the next action needs the new weights

    return per_step_ms(step, steps)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--json")
    args = parser.parse_args()
    torch.set_num_threads(1)
    cuda = torch.cuda.is_available()
    results: dict[str, Any] = {
        "machine": platform.machine(),
        "python": platform.python_version(),
        "torch": torch.__version__,
        "gpu": torch.cuda.get_device_name() if cuda else None,
        "rounds": args.rounds,
        "steps": args.steps,
        "members": {},
    }
    print(
        f"\n{args.rounds} rounds of {args.steps} steps; torch {torch.__version__} "
        f"(1 CPU thread){'; ' + results['gpu'] if cuda else ''}\n"
    )
    print(
        "| learners | separate (ms per step) | batched, CPU | ratio |"
        + (" batched, CUDA graph | ratio |" if cuda else "")
    )
    print("|---:|---:|---:|---:|" + ("---:|---:|" if cuda else ""))
    for members in (1, 5, 10):
        row = {
            "separate_ms": statistics.median(
                separate_ms(members, args.steps) for _ in range(args.rounds)
            ),
            "cpu_ms": statistics.median(
                ensemble_ms(members, "cpu", args.steps) for _ in range(args.rounds)
            ),
        }
        line = (
            f"| {members} | {row['separate_ms']:.2f} | {row['cpu_ms']:.2f} | "
            f"{row['separate_ms'] / row['cpu_ms']:.1f}x |"
        )
        if cuda:
            row["cuda_ms"] = statistics.median(
                ensemble_ms(members, "cuda", args.steps) for _ in range(args.rounds)
            )
            line += f" {row['cuda_ms']:.2f} | {row['separate_ms'] / row['cuda_ms']:.1f}x |"
        results["members"][members] = row
        print(line)
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()
