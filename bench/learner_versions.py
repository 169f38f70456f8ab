"""The learners of another commit beside this checkout's: did a change make them faster?

The other commit's ``client/agents`` package is loaded as a package of its own, and its
learners take turns with this checkout's in one process: one run's learner (``DDPG``) and
lockstep ensembles (``DDPGEnsemble``) of 1, 5 and 10 members, of the same seeds and holding
the same transitions. Each round times a block of training steps (an update and an action of
every member, as ``bench/learner.py``) of one, then of the other, the order swapped every
round, so that a drift of the machine's speed falls on both. Reported per learner: the
medians over rounds and the median of the rounds' ratios; and whether both hold the same
weights, bit for bit, once they have taken all their steps.

    python bench/learner_versions.py 8720798 --json bench/results/learner_versions_8720798.json
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import tempfile
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.learner import CONFIG, fill  # noqa: E402
from bench.versions import load_package, paired, table_row  # noqa: E402
from client.agents import ddpg as this_ddpg  # noqa: E402
from client.agents import ensemble as this_ensemble  # noqa: E402

SIZES = (1, 5, 10)


def block_ms(learner: Any, obs: np.ndarray, steps: int) -> float:
    """Milliseconds per training step over a block of ``steps``."""
    start = time.perf_counter()
    for _ in range(steps):
        learner.update()
        learner.act(obs, explore=False)
    return (time.perf_counter() - start) / steps * 1e3


def weights(learner: Any) -> list[torch.Tensor]:
    """Every weight and target weight of a learner of either kind."""
    if hasattr(learner, "members"):
        return [*learner.actor, *learner.critic, *learner.actor_target, *learner.critic_target]
    return [
        p.detach()
        for net in (learner.actor, learner.critic, learner.actor_target, learner.critic_target)
        for p in net.parameters()
    ]


def compare(learners: dict[str, Any], obs: np.ndarray, rounds: int, steps: int) -> dict[str, Any]:
    for learner in learners.values():  # warm-up: allocator, first Adam steps
        block_ms(learner, obs, 10)
    times: dict[str, list[float]] = {"other": [], "this": []}
    for r in range(rounds):
        for name in ("other", "this") if r % 2 == 0 else ("this", "other"):
            times[name].append(block_ms(learners[name], obs, steps))
    identical = all(
        torch.equal(x, y)
        for x, y in zip(weights(learners["other"]), weights(learners["this"]), strict=True)
    )
    return {**paired(times["other"], times["this"]), "identical": identical}


def separate(other: ModuleType, rounds: int, steps: int) -> dict[str, Any]:
    """One run's learner of each commit."""
    learners = {"other": other.ddpg.DDPG(CONFIG, 0), "this": this_ddpg.DDPG(CONFIG, 0)}
    for learner in learners.values():  # each from the same generator: the same transitions
        fill([learner])
    return compare(learners, np.full(4, 10.0, np.float32), rounds, steps)


def ensembles(other: ModuleType, members: int, rounds: int, steps: int) -> dict[str, Any]:
    """A lockstep ensemble of ``members`` of each commit."""
    seeds = list(range(members))
    learners = {
        "other": other.ensemble.DDPGEnsemble(CONFIG, seeds),
        "this": this_ensemble.DDPGEnsemble(CONFIG, seeds),
    }
    for learner in learners.values():
        fill(learner.members)
    return compare(learners, np.full((members, 4), 10.0, np.float32), rounds, steps)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("commit", help="the commit whose learners are the baseline")
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--json", help="also write the results here")
    args = parser.parse_args()
    torch.set_num_threads(1)
    with tempfile.TemporaryDirectory() as directory:
        other = load_package(args.commit, "client/agents", Path(directory))
        results: dict[str, Any] = {
            "machine": platform.machine(),
            "processor": platform.processor(),
            "python": platform.python_version(),
            "torch": torch.__version__,
            "baseline": args.commit,
            "rounds": args.rounds,
            "steps": args.steps,
            "learners": {},
        }
        print(
            f"\n{args.rounds} rounds of {args.steps} steps; torch {torch.__version__} "
            f"(1 CPU thread)\n"
        )
        print(
            f"| learner | {args.commit} (ms per step) | this checkout | speed-up (paired) "
            f"| identical weights |"
        )
        print("|---|---:|---:|---:|---|")
        rows: list[tuple[str, Callable[[], dict[str, Any]]]] = [
            ("one run (DDPG)", lambda: separate(other, args.rounds, args.steps))
        ] + [
            (
                f"lockstep, {m} run{'s' if m > 1 else ''}",
                partial(ensembles, other, m, args.rounds, args.steps),
            )
            for m in SIZES
        ]
        for label, measure in rows:
            row = measure()
            results["learners"][label] = row
            print(table_row(label, row, row["identical"]))
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()
