"""Cost of counting the outcome log again under the current states (the risk reviser's
recount, :mod:`app.core.outcome_log`) as the model grows.

Each model has n states spread over the normalised cube and a full log of the default
200,000 transitions (observations drifting through the cube, one in 200 a failure). A full
log recounts when it makes room: its older half goes into the base, the rest is counted again,
and the next recount comes 100,000 transitions later; the amortised cost per step is that
recount spread over them. Reported: the median over rounds of one recount, and per step.

    python bench/recount.py                     # 10, 1000 and 5000 states
    python bench/recount.py --sizes 10 1000 --rounds 3
"""

from __future__ import annotations

import argparse
import copy
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from app.core import LimitsConfig, Shield, ShieldConfig  # noqa: E402
from app.core.outcome_log import OutcomeLog  # noqa: E402
from bench.core_step import spread  # noqa: E402

CAPACITY = LimitsConfig().outcome_log


def build(n: int, seed: int = 0) -> tuple[Shield, OutcomeLog]:
    """A shield of n states and a full log of transitions among them."""
    config = ShieldConfig(limits=LimitsConfig(max_states=n))
    rng = np.random.default_rng(seed)
    shield = spread(config, n, rng)
    log = OutcomeLog(3, config.action.n_bins, len(config.criteria), n, CAPACITY)
    for _ in range(n):
        log.add_state()
    z = rng.uniform(0, 1, 3)
    for _ in range(CAPACITY):
        after = np.clip(z + rng.normal(0, 0.03, 3), 0, 1)
        failed = rng.random() < 0.005
        log.append(z, int(rng.integers(20)), None if failed else after,
                   int(rng.integers(2)) if failed else None)
        z = after
    return shield, log


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[10, 1000, 5000])
    parser.add_argument("--rounds", type=int, default=5)
    args = parser.parse_args()
    print(f"machine: {platform.processor() or platform.machine()}, numpy {np.__version__}, "
          f"log of {CAPACITY} transitions\n")
    print("| states | recount of a full log (ms) | per step, amortised (us) |")
    print("|---:|---:|---:|")
    for n in args.sizes:
        shield, log = build(n)
        most_likely = shield.clusterer.most_likely
        copy.deepcopy(log).recount(most_likely, 0)  # compiled
        times = []
        for _ in range(args.rounds):
            fresh = copy.deepcopy(log)
            start = time.perf_counter()
            fresh.recount(most_likely, 0)
            times.append(time.perf_counter() - start)
        cost = statistics.median(times)
        print(f"| {n} | {cost * 1e3:.1f} | {cost / (CAPACITY // 2) * 1e6:.2f} |")


if __name__ == "__main__":
    main()
