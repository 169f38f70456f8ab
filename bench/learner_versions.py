"""The lockstep learner of another commit beside this checkout's: did a change make it faster?

The other commit's ``client/agents/ensemble.py`` is loaded as a module of its own (it must
share this checkout's ``client/agents/ddpg.py``, which it builds its members from), and both
ensembles, of the same seeds and holding the same transitions, take turns in one process:
each round times a block of training steps (an update and an action of every member, as
``bench/learner.py``) of one, then of the other, the order swapped every round, so that a
drift of the machine's speed falls on both. Reported per ensemble size: the medians over
rounds and the median of the rounds' ratios; and whether both ensembles hold the same weights,
bit for bit, once they have taken all their steps.

    python bench/learner_versions.py f1e79d3 --rounds 7 --json bench/results/learner_versions.json
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.learner import CONFIG, fill  # noqa: E402
from client.agents import ensemble as this  # noqa: E402

SIZES = (1, 5, 10)


def load_ensemble(commit: str, directory: Path) -> ModuleType:
    """``client/agents/ensemble.py`` as it was at ``commit``."""
    def show(path: str) -> str:
        return subprocess.run(["git", "show", f"{commit}:{path}"], cwd=ROOT, check=True,
                              capture_output=True, text=True).stdout

    if show("client/agents/ddpg.py") != (ROOT / "client/agents/ddpg.py").read_text():
        sys.exit(f"{commit} has another client/agents/ddpg.py: the two learners would differ "
                 f"in more than the ensemble")
    source = directory / f"ensemble_{commit}.py"
    source.write_text(show("client/agents/ensemble.py"))
    spec = importlib.util.spec_from_file_location(f"ensemble_{commit}", source)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def block_ms(learner: Any, obs: np.ndarray, steps: int) -> float:
    """Milliseconds per training step over a block of ``steps``."""
    start = time.perf_counter()
    for _ in range(steps):
        learner.update()
        learner.act(obs, explore=False)
    return (time.perf_counter() - start) / steps * 1e3


def same_weights(a: Any, b: Any) -> bool:
    return all(torch.equal(x, y) for x, y in zip(
        [*a.actor, *a.critic, *a.actor_target, *a.critic_target],
        [*b.actor, *b.critic, *b.actor_target, *b.critic_target], strict=True))


def compare(other: ModuleType, members: int, rounds: int, steps: int) -> dict[str, Any]:
    seeds = list(range(members))
    learners = {"other": other.DDPGEnsemble(CONFIG, seeds),
                "this": this.DDPGEnsemble(CONFIG, seeds)}
    for learner in learners.values():
        fill(learner.members)
    obs = np.full((members, 4), 10.0, np.float32)
    for learner in learners.values():  # warm-up: allocator, first Adam steps
        block_ms(learner, obs, 10)
    times: dict[str, list[float]] = {"other": [], "this": []}
    for r in range(rounds):
        for name in ("other", "this") if r % 2 == 0 else ("this", "other"):
            times[name].append(block_ms(learners[name], obs, steps))
    return {"other_ms": statistics.median(times["other"]),
            "this_ms": statistics.median(times["this"]),
            "speed_up": statistics.median(o / t for o, t in zip(times["other"], times["this"],
                                                                strict=True)),
            "rounds": times, "identical": same_weights(learners["other"], learners["this"])}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("commit", help="the commit whose ensemble is the baseline")
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--json", help="also write the results here")
    args = parser.parse_args()
    torch.set_num_threads(1)
    with tempfile.TemporaryDirectory() as directory:
        other = load_ensemble(args.commit, Path(directory))
        results: dict[str, Any] = {
            "machine": platform.machine(), "processor": platform.processor(),
            "python": platform.python_version(), "torch": torch.__version__,
            "baseline": args.commit, "rounds": args.rounds, "steps": args.steps, "members": {}}
        print(f"\n{args.rounds} rounds of {args.steps} steps; torch {torch.__version__} "
              f"(1 CPU thread)\n")
        print(f"| learners | {args.commit} (ms per step) | this checkout | speed-up (paired) "
              f"| identical weights |")
        print("|---:|---:|---:|---:|---|")
        for members in SIZES:
            row = compare(other, members, args.rounds, args.steps)
            results["members"][members] = row
            print(f"| {members} | {row['other_ms']:.2f} | {row['this_ms']:.2f} | "
                  f"{row['speed_up']:.2f}x | {'yes' if row['identical'] else 'no'} |")
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()
