"""How far lockstep learners drift from separate runs over 300 updates, and why.

The same three DDPG runs are trained twice on the same observations and rewards, each path
from its own actions: as separate learners on the CPU and as one batched ensemble. Per window
of 50 steps, the largest difference between the two paths' actions. Rows:

* ``cpu``: the ensemble on the CPU, where most operations round as the separate runs' do;
* ``cpu + noise R``: the same, every weight multiplied by (1 + R x a standard normal) after
  each update, R about one float32 unit in the last place: what learning makes of
  rounding-sized differences at every update;
* ``cuda``: the ensemble as a CUDA graph, where almost every operation rounds differently.

    python bench/rounding_drift.py
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np
import numpy.typing as npt
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from client.agents.ddpg import DDPG, DDPGConfig  # noqa: E402
from client.agents.ensemble import DDPGEnsemble  # noqa: E402

STEPS, WINDOW, SEEDS = 300, 50, [11, 12, 13]
CONFIG = DDPGConfig(warmup=64)


def train_side_by_side(
    ensemble: DDPGEnsemble, single: list[DDPG], steps: int, noise: float = 0.0
) -> tuple[list[float], npt.NDArray[np.float32]]:
    """Train the ensemble and the separate learners on the same observations and rewards,
    each from its own actions; with ``noise``, nudge the ensemble's weights after each update.
    The largest action difference of every step, and the observations that come next."""
    rng, nudges = np.random.default_rng(0), torch.Generator().manual_seed(0)
    n = len(single)
    obs = rng.uniform(0, 30, (n, 4)).astype(np.float32)
    worst = []
    for _ in range(steps):
        batched = ensemble.act(obs)
        alone = [agent.act(o) for agent, o in zip(single, obs, strict=True)]
        worst.append(float(np.max(np.abs(np.subtract(batched, alone)))))
        following = rng.uniform(0, 30, (n, 4)).astype(np.float32)
        reward = rng.uniform(-3, 0, n)
        for k in range(n):
            ensemble.members[k].remember(obs[k], batched[k], reward[k], following[k], False)
            single[k].remember(obs[k], alone[k], reward[k], following[k], False)
        ensemble.update()
        for agent in single:
            agent.update()
        if noise and single[0].buffer.count >= CONFIG.warmup:
            with torch.no_grad():
                for p in [
                    *ensemble.actor,
                    *ensemble.critic,
                    *ensemble.actor_target,
                    *ensemble.critic_target,
                ]:
                    p.mul_(1 + noise * torch.randn(p.shape, generator=nudges))
        obs = following
    return worst, obs


def drift(device: str, noise: float = 0.0) -> list[float]:
    """The largest action difference in every window of ``WINDOW`` steps."""
    ensemble = DDPGEnsemble(CONFIG, SEEDS, device)
    worst, _ = train_side_by_side(ensemble, [DDPG(CONFIG, s) for s in SEEDS], STEPS, noise)
    return [max(worst[i : i + WINDOW]) for i in range(0, STEPS, WINDOW)]


def main() -> None:
    torch.set_num_threads(1)
    os.environ.setdefault("CUBLAS_WORKSPACE_CONFIG", ":4096:8")  # as the runner: deterministic
    rows = [
        ("cpu", "cpu", 0.0),
        ("cpu + noise 6e-8", "cpu", 6e-8),
        ("cpu + noise 3e-7", "cpu", 3e-7),
    ]
    if torch.cuda.is_available():
        rows.append(("cuda", "cuda", 0.0))
    windows = " | ".join(f"{i}-{i + WINDOW - 1}" for i in range(0, STEPS, WINDOW))
    print(f"| path | {windows} |\n|---|" + "---:|" * (STEPS // WINDOW))
    for name, device, noise in rows:
        print(f"| {name} | " + " | ".join(f"{d:.1e}" for d in drift(device, noise)) + " |")


if __name__ == "__main__":
    main()
