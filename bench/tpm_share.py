"""What learning the transition matrices costs a step of the risk reviser, which never reads them.

Under the default reviser the decision reads the local risk model and the reach; the
transition matrices (Eqs. 3-4) and the flags are learned for the views (a state's next states
and flags in ``GET /models/{name}/states/{i}`` and the dashboard) and for a switch to the paper's
reviser on the same model. This times :mod:`bench.step_cost`'s model and keep workload with the
transitions learned, as the shield does, and without (the step told that no transition is
learned), in alternating rounds on one model each, and reports the medians and their ratio.

    python bench/tpm_share.py --sizes 10 1000 --rounds 7
"""

from __future__ import annotations

import argparse
import platform
import statistics
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from app.core import Shield  # noqa: E402
from bench.step_cost import SEED, build, steps, time_steps  # noqa: E402


def without_transitions(shield: Shield) -> Shield:
    """``shield``, its step told that no transition is learned (everything else as it is)."""
    shield._transition_bin = lambda *_: -1  # type: ignore[method-assign]
    return shield


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[10, 1000])
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--steps", type=int, default=3000)
    args = parser.parse_args()
    print(
        f"seed {SEED}, keep workload; {args.rounds} alternating rounds of {args.steps} steps, "
        f"median of round means; {platform.machine()}, numpy {np.__version__}, "
        f"Python {platform.python_version()}\n"
    )
    print("| states | learned (us) | not learned (us) | transitions' share |")
    print("|---:|---:|---:|---:|")
    for n in args.sizes:
        learned, skipped = build(n), without_transitions(build(n))
        for shield in (learned, skipped):
            time_steps(shield, steps(200, SEED + 99, "keep"))  # compiled and warm
        times: dict[str, list[float]] = {"learned": [], "skipped": []}
        for r in range(args.rounds):
            block = steps(args.steps, SEED + r, "keep")
            times["learned"].append(time_steps(learned, block)[0])
            times["skipped"].append(time_steps(skipped, block)[0])
        a, b = (statistics.median(times[k]) * 1e6 for k in ("learned", "skipped"))
        print(f"| {n} | {a:.1f} | {b:.1f} | {1 - b / a:.0%} |")


if __name__ == "__main__":
    main()
