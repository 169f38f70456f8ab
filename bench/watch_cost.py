"""What the live view costs the step path: nothing to speak of when nobody watches.

With nobody watching, a step pays one test of an empty list (``if model.watchers``); this
measures that test, the registry step with no watcher, and the step with one watcher whose
callback does nothing (the event is still built), in the same run. Medians of rounds.

    python bench/watch_cost.py
"""

from __future__ import annotations

import statistics
import sys
import time
import timeit
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from app.service.registry import ModelRegistry, Step  # noqa: E402
from tests.utils import random_stream  # noqa: E402

ROUNDS, STEPS = 7, 1000


def per_step(registry: ModelRegistry, seed: int) -> float:
    stream = [Step(z, None if d else a, done=d) for z, a, d in random_stream(seed, STEPS)]
    start = time.perf_counter()
    for step in stream:
        registry.step("default", step)
    return (time.perf_counter() - start) / STEPS


def main() -> None:
    quiet, watched = ModelRegistry(), ModelRegistry()
    quiet.open()
    watched.open()
    watched.watch("default", lambda event: None)
    check = (
        min(
            timeit.repeat(
                "m.watchers and None",
                globals={"m": quiet.get("default")},
                number=1_000_000,
                repeat=5,
            )
        )
        / 1_000_000
    )
    no_watcher = statistics.median(per_step(quiet, r) for r in range(ROUNDS))
    one_watcher = statistics.median(per_step(watched, r) for r in range(ROUNDS))
    print(f"\n{ROUNDS} rounds of {STEPS} steps, seed 0..{ROUNDS - 1}\n")
    print("| what | per step |")
    print("|---|---:|")
    print(f"| the empty-list test a step pays when nobody watches | {check * 1e9:.0f} ns |")
    print(f"| registry step, nobody watching | {no_watcher * 1e6:.1f} us |")
    print(f"| registry step, one watcher | {one_watcher * 1e6:.1f} us |")
    print(f"\nshare of a step spent on the live view when nobody watches: {check / no_watcher:.4%}")


if __name__ == "__main__":
    main()
