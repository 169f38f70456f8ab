"""What the risk reviser's kernels cost inside a step, where a loop over them alone misleads.

A kernel timed alone in a loop runs on warm caches; inside a step it follows the clustering,
the learning and Python's own work, and costs more. This runs :mod:`bench.step_cost`'s model
and keep workload and, on every step that decides, times the reach
(:func:`app.core.reach.risk`) and the local model's read (:func:`app.core.local_risk._read`)
again on that step's own arrays, right after the step's compiled call. Reported: the medians
over the steps of the whole step (timed on a copy of the model without the timers), of its
two compiled calls (the clustering and recognition; the learning and the decision) and of
the reach and the read within the second. Compare commits by running it in a worktree of
each, in the same session.

    python bench/reach_cost.py --states 10 1000
"""

from __future__ import annotations

import argparse
import platform
import statistics
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import app.core.shield as shield_module  # noqa: E402
from app.core import local_risk, reach  # noqa: E402
from bench.step_cost import SEED, build, steps, time_steps  # noqa: E402

NO_COV = np.zeros((0, 0, 0))  # the dynamics' covariances, which the reach's risk does not read

COLUMNS = (
    "the whole step",
    "clustering and recognition",
    "learning and the decision",
    "the reach",
    "the read",
)


def measure(n: int, count: int) -> dict[str, float]:
    """Median microseconds of the whole step, its two compiled calls, and the reach and the
    read within the second, at n states."""
    times: dict[str, list[float]] = {name: [] for name in COLUMNS}
    bare = build(n)
    time_steps(bare, steps(200, SEED + 99, "keep"))  # compiled and warm
    for z, a in steps(count, SEED, "keep"):
        start = time.perf_counter()
        bare.step(z, a)
        times["the whole step"].append(time.perf_counter() - start)

    shield = build(n)
    time_steps(shield, steps(200, SEED + 99, "keep"))
    module: Any = shield_module  # its two compiled calls are swapped for timed ones below
    first_call, compiled_call = module.observe, module.learn_and_decide

    def timed_first(*args: Any) -> Any:
        start = time.perf_counter()
        result = first_call(*args)
        times["clustering and recognition"].append(time.perf_counter() - start)
        return result

    def timed(*args: Any) -> Any:
        start = time.perf_counter()
        result = compiled_call(*args)
        times["learning and the decision"].append(time.perf_counter() - start)
        decide, (local, safe, _, _) = args[9][7], args[2]
        if decide and result[2]:
            index, prob, z, out = args[6], args[7], args[8], np.empty_like(args[10])
            theta, tried, low, high, extent, midpoints = (local[i] for i in (1, 3, 4, 5, 6, 7))
            start = time.perf_counter()
            reach.risk(local[13], extent, midpoints, index, prob, z, safe, out)
            times["the reach"].append(time.perf_counter() - start)
            start = time.perf_counter()
            local_risk._read(theta, tried, low, high, index, prob, z, midpoints, safe, out)
            times["the read"].append(time.perf_counter() - start)
        return result

    module.observe, module.learn_and_decide = timed_first, timed
    try:
        time_steps(shield, steps(count, SEED, "keep"))
    finally:
        module.observe, module.learn_and_decide = first_call, compiled_call
    return {name: statistics.median(values) * 1e6 for name, values in times.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--states", type=int, nargs="+", default=[10, 1000])
    parser.add_argument("--steps", type=int, default=3000)
    args = parser.parse_args()
    print(
        f"seed {SEED}, keep workload, {args.steps} steps, medians; {platform.machine()}, "
        f"Python {platform.python_version()}\n"
    )
    print("| states | " + " | ".join(f"{name} (us)" for name in COLUMNS) + " |")
    print("|---:|" + "---:|" * len(COLUMNS))
    for n in args.states:
        row = measure(n, args.steps)
        print(f"| {n} | " + " | ".join(f"{value:.1f}" for value in row.values()) + " |")


if __name__ == "__main__":
    main()
