"""Cost of the risk reviser as the model grows: the refresh of the risk table (value iteration
over the counted outcomes) and the per-step read of it (the risk of every action under a
belief of 16 states, and the choice).

Each model has n states, 20 actions and 2 criteria; 40 tries per state along a random walk
over nearby states (about 20 distinct moves per state), one try in 200 a failure. Reported:
the median over rounds of each cost, and its ratio to the 10-state model's in the same run.

    python bench/risk_refresh.py                     # 10, 1000 and 5000 states, horizon 8
    python bench/risk_refresh.py --sizes 10 1000 --rounds 3 --horizon 20
"""

from __future__ import annotations

import argparse
import platform
import statistics
import time

import numpy as np

from app.core.risk import OutcomeCounts, decide, horizon_risk, safe_steps

ACTIONS, CRITERIA = 20, 2
DIRECTIONS = ("decrease", "increase")


def build(n: int, seed: int = 0) -> OutcomeCounts:
    """Counts of a learned model of n states."""
    rng = np.random.default_rng(seed)
    counts = OutcomeCounts(ACTIONS, CRITERIA, max_states=n)
    for _ in range(n):
        counts.add_state()
    for state in range(n):
        for _ in range(40):
            action = int(rng.integers(ACTIONS))
            if rng.random() < 0.005:
                counts.learn_failure(state, action, int(rng.integers(CRITERIA)))
            else:
                nxt = int(np.clip(state + rng.integers(-10, 11), 0, n - 1))
                counts.learn_move(state, action, nxt)
    return counts


def timed(fn: object, repeat: int) -> float:
    """Mean seconds of ``repeat`` calls."""
    start = time.perf_counter()
    for _ in range(repeat):
        fn()  # type: ignore[operator]
    return (time.perf_counter() - start) / repeat


def measure(n: int, rounds: int, horizon: int) -> tuple[int, float, float, int]:
    """States, median refresh and per-step read (seconds), and the number of moves."""
    counts = build(n)
    moves = counts.moves()
    table = horizon_risk(counts.tries, counts.failures, moves, DIRECTIONS, horizon, 1.0)
    rng = np.random.default_rng(1)
    index = np.sort(rng.choice(n, size=min(16, n), replace=False)).astype(np.int64)
    prob = np.full(index.size, 1.0 / index.size)
    safe = safe_steps(DIRECTIONS)
    by_bin = np.empty((ACTIONS, CRITERIA))
    verdicts = np.empty(ACTIONS, dtype=np.int64)

    def refresh() -> None:
        horizon_risk(counts.tries, counts.failures, moves, DIRECTIONS, horizon, 1.0)

    def read() -> None:
        decide(table, index, prob, 15, 0.0, 0.001, safe, by_bin, verdicts)

    refreshes = [timed(refresh, 3) for _ in range(rounds)]
    reads = [timed(read, 2000) for _ in range(rounds)]
    return n, statistics.median(refreshes), statistics.median(reads), moves[0].size


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[10, 1000, 5000])
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--horizon", type=int, default=8)
    args = parser.parse_args()
    print(f"machine: {platform.processor() or platform.machine()}, horizon {args.horizon}")
    rows = [measure(n, args.rounds, args.horizon) for n in args.sizes]
    base_refresh, base_step = rows[0][1], rows[0][2]
    print("| states | moves | refresh (ms) | x smallest | per-step read (us) | x smallest |")
    print("|---:|---:|---:|---:|---:|---:|")
    for n, r, s, m in rows:
        print(f"| {n} | {m} | {r * 1e3:.2f} | {r / base_refresh:.1f} | {s * 1e6:.1f} | "
              f"{s / base_step:.2f} |")


if __name__ == "__main__":
    main()
