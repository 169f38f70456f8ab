"""How fast each protocol layout of a ``bench/device.sh`` call trained, from its records.

Every layout ran the paper's protocol from episode 1 for the same fixed time; this reads the
``NAME.tar.gz`` files it brought back (steps and ``wall_s`` of every episode) and prints, per
layout and arm, the episodes reached, the time of one training step of one run (in lockstep,
the time of one step of the whole group) and the steps per second of all ten runs together.

    python bench/device_pace.py bench/results/device-h200/*.tar.gz
"""

from __future__ import annotations

import argparse
import json
import statistics
import tarfile
from collections import defaultdict
from pathlib import Path

ARMS = {"ddpg": "ddpg", "ddpg_shield": "ddpg+shield"}


def runs_of(archive: Path) -> dict[str, list[tuple[int, int, float]]]:
    """Per arm, (episodes, steps, episode seconds) of every run in the archive."""
    runs: dict[str, list[tuple[int, int, float]]] = defaultdict(list)
    with tarfile.open(archive) as tar:
        for member in sorted(tar.getmembers(), key=lambda m: m.name):
            path = Path(member.name)
            if path.parent.name != "records" or path.suffix != ".jsonl":
                continue
            arm = ARMS[path.stem.split("__")[0]]
            stream = tar.extractfile(member)
            assert stream is not None
            episodes = [json.loads(line) for line in stream.read().splitlines()[1:]]
            runs[arm].append(
                (
                    len(episodes),
                    sum(e["steps"] for e in episodes),
                    sum(e["wall_s"] for e in episodes),
                )
            )
    return runs


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("archives", nargs="+", type=Path)
    args = parser.parse_args()
    print(
        "| layout | arm | episodes reached | ms per step of a run (median) "
        "| steps per second, all runs |"
    )
    print("|---|---|---:|---:|---:|")
    for archive in args.archives:
        for arm, runs in runs_of(archive).items():
            episodes = [e for e, _, _ in runs]
            per_step = statistics.median(wall / steps * 1e3 for _, steps, wall in runs)
            rate = sum(s for _, s, _ in runs) / max(w for _, _, w in runs)
            print(
                f"| {archive.name.removesuffix('.tar.gz')} | {arm} | "
                f"{min(episodes)}-{max(episodes)} | {per_step:.2f} | {rate:,.0f} |"
            )


if __name__ == "__main__":
    main()
