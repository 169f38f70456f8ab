"""The shield's share of the shielded arm's time in the paper's protocol, in-process.

Runs the first episodes of the protocol's shielded arm (DDPG with the default shield, ten runs
stepping together in one process, one batched update a step, as ``python -m client run
--lockstep`` runs them) with a timer around every :meth:`Shield.step`, and reports the time in
the shields against the whole run's, and both per lockstep step. The first 50 episodes are
the reviser's inactive ones (it learns, it does not revise), so ``--episodes`` beyond 50 shows
the active shield too. The compiled core is loaded before the clock starts (its first calls
in a process load the kernels from the cache, about half a second that a full protocol
spreads over hours).

    python -m bench.protocol_share --episodes 60
"""

from __future__ import annotations

import argparse
import platform
import tempfile
import time
from pathlib import Path
from typing import Any

from app.core import compiled
from app.core.shield import Shield
from client.experiment.lockstep import run_lockstep
from client.experiment.runner import ExperimentConfig

ARM = "ddpg+shield"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--runs", type=int, default=10)
    parser.add_argument("--episodes", type=int, default=60)
    parser.add_argument("--seed", type=int, default=7)
    args = parser.parse_args()
    compiled.warm()
    spent = [0.0, 0]
    step = Shield.step

    def timed(self: Shield, *a: Any, **k: Any) -> Any:
        start = time.perf_counter()
        try:
            return step(self, *a, **k)
        finally:
            spent[0] += time.perf_counter() - start
            spent[1] += 1

    Shield.step = timed  # type: ignore[method-assign]
    config = ExperimentConfig(arms=(ARM,), runs=args.runs, episodes=args.episodes, seed=args.seed)
    with tempfile.TemporaryDirectory() as out:
        start = time.perf_counter()
        run_lockstep(config, ARM, Path(out))
        total = time.perf_counter() - start
    shield, calls = spent
    rounds = calls / args.runs
    print(
        f"{args.runs} runs x {args.episodes} episodes, seed {args.seed}, in-process shields; "
        f"{platform.machine()}, Python {platform.python_version()}\n"
    )
    print("| | seconds | per lockstep step (ms) | share |")
    print("|---|---:|---:|---:|")
    print(f"| the shielded arm | {total:.1f} | {total / rounds * 1e3:.2f} | 100% |")
    print(
        f"| its shields ({calls} steps, {shield / calls * 1e6:.0f} us each) | {shield:.1f} | "
        f"{shield / rounds * 1e3:.2f} | {shield / total:.1%} |"
    )


if __name__ == "__main__":
    main()
