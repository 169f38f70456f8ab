"""The shield's last decisions before each failure in one run of a world of ``bench/worlds``.

Runs the world as ``python -m bench.worlds`` does (the same seed, episodes and warm-up, so the
same failures), and for every failure after the warm-up prints the last ``--last`` steps:
the shield's observation, the action applied, why, the proposal's risk per criterion, the
limit, and the recognised state.

    python results/scripts/world_failures.py tuning_flat_out --seed 2 --episodes 500
"""

from __future__ import annotations

import argparse
import sys
from collections import deque
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from app.core import Shield  # noqa: E402
from bench.worlds.__main__ import world_named  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("world")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--episodes", type=int, default=150)
    parser.add_argument("--warmup", type=int, default=50)
    parser.add_argument("--last", type=int, default=40)
    args = parser.parse_args()
    world = world_named(args.world)
    env, act, shield = world.make(args.seed), world.controller(args.seed), Shield(world.config)
    out = sys.stdout
    for episode in range(args.episodes):
        observation, _ = env.reset(seed=args.seed * 100_003 + episode)  # as the harness
        if hasattr(act, "reset"):
            act.reset()
        last: deque[str] = deque(maxlen=args.last)
        event = None
        for t in range(world.max_steps):
            z = world.shield_observation(observation)
            d = shield.step(z, float(act(observation)), stream="0")
            risk = ", ".join(f"{k} {v:.3f}" for k, v in d.risk.items())
            limit = "-" if d.threshold is None else f"{d.threshold:.4f}"
            last.append(
                f"  step {t}: z {[round(v, 1) for v in z]}, applied {d.action:.2f} "
                f"({d.reason}), proposal's risk {risk}, limit {limit}, state {d.state}"
            )
            observation, _, terminated, truncated, info = env.step(np.array([float(d.action)]))
            event = world.event(observation, info)
            if event is not None or terminated or truncated:
                break
        shield.step(world.shield_observation(observation), None, stream="0", done=True, event=event)
        if event is not None and episode >= args.warmup:
            out.write(f"episode {episode}: {event} at step {t}, {shield.n_states} states\n")
            out.write("\n".join(last) + "\n")


if __name__ == "__main__":
    main()
