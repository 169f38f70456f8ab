"""``python -m bench.heldout.calibrate``: how often each held-out world's controller fails
alone (no shield is built), per world and seed, in the episodes before and after the warm-up
that a shielded evaluation would use, as a Markdown table.

Example::

    python -m bench.heldout.calibrate --seeds 2000-2008 --episodes 250 --warmup 50
"""

from __future__ import annotations

import argparse
import platform
import subprocess
from collections import Counter
from collections.abc import Callable, Sequence

from bench.heldout import NAMES, world
from bench.worlds.harness import World, run


def kinds_text(failures: dict[str, int]) -> str:
    """Failures by kind, ``chill 35, overheat 39``."""
    return ", ".join(f"{kind} {count}" for kind, count in sorted(failures.items()))


def seed_list(text: str) -> list[int]:
    """Seeds written ``2000-2008`` or ``2000,2003``."""
    if "-" in text:
        first, last = (int(part) for part in text.split("-"))
        return list(range(first, last + 1))
    return [int(part) for part in text.split(",")]


def main() -> None:
    calibrate(NAMES, world, __doc__.splitlines()[0])


def calibrate(names: Sequence[str], world: Callable[[str], World], description: str) -> None:
    """The command line of a set of held-out worlds (``names``, ``world(name)``): each
    controller alone, per world and seed, as a Markdown table."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--worlds", default=",".join(names))
    parser.add_argument("--seeds", default="2000-2008")
    parser.add_argument("--episodes", type=int, default=250)
    parser.add_argument("--warmup", type=int, default=50)
    args = parser.parse_args()
    seeds = seed_list(args.seeds)
    commit = (
        subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, check=False
        ).stdout.strip()
        or "unknown"
    )
    print(
        f"Controller alone (config=None), {args.episodes} episodes a seed; "
        f"episodes 1-{args.warmup} and {args.warmup + 1}-{args.episodes} counted apart. "
        f"Commit {commit}, {platform.processor() or platform.machine()}, "
        f"Python {platform.python_version()}.\n"
    )
    print(
        f"| world | seed | failures 1-{args.warmup} | failures {args.warmup + 1}-"
        f"{args.episodes} | rate {args.warmup + 1}-{args.episodes} | rate 1-{args.episodes} | "
        f"by kind, {args.warmup + 1}-{args.episodes} |"
    )
    print("|---|---|---|---|---|---|---|")
    for name in args.worlds.split(","):
        chosen = world(name)
        early_total = late_total = 0
        kinds: Counter[str] = Counter()
        for seed in seeds:
            early = run(chosen, seed, args.warmup, 0, None)  # the same episodes' first part
            late = run(chosen, seed, args.episodes, args.warmup, None)
            early_total += early["total"]
            late_total += late["total"]
            kinds.update(late["failures"])
            print(
                f"| {name} | {seed} | {early['total']} | {late['total']} | "
                f"{late['total'] / late['episodes']:.1%} | "
                f"{(early['total'] + late['total']) / args.episodes:.1%} | "
                f"{kinds_text(late['failures'])} |",
                flush=True,
            )
        episodes = (args.episodes - args.warmup) * len(seeds)
        print(
            f"| **{name}** | all | {early_total} | {late_total} | "
            f"**{late_total / episodes:.1%}** | "
            f"**{(early_total + late_total) / (args.episodes * len(seeds)):.1%}** | "
            f"{kinds_text(dict(kinds))} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
