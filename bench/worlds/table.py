"""``python -m bench.worlds.table FILE [FILE ...]``: the figures #68 asks of every evaluation, as
a Markdown table, from the JSON files ``python -m bench.worlds --out`` writes.

A row a world: failures after the warm-up alone and shielded, their ratio and the worst seed's,
the seeds where the shield did worse than the controller alone (after the warm-up, and within
it), the warm-up's failures, the share of steps revised, the mean size of a revision and the
controller's own task figure alone and shielded (lower is better; "-" where the world reports
none).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

HEADER = (
    "| world | failures alone | shielded | ratio | worst seed | seeds worse than alone | "
    "warm-up alone / shielded | seeds worse in the warm-up | steps revised | "
    "mean revision | task alone / shielded |\n"
    "|---|---:|---:|---:|---:|---|---:|---|---:|---:|---:|"
)


def _figure(value: float | None, digits: int = 2) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


def row(result: dict[str, Any]) -> str:
    """One world's line of the table."""
    runs = result["runs"]
    revised = sum(r["shielded"]["revised"] for r in runs)
    steps = sum(r["shielded"]["steps"] for r in runs)
    size = sum(r["shielded"]["mean_revision"] * r["shielded"]["revised"] for r in runs)
    tasks = [
        (r["alone"]["task"], r["shielded"]["task"]) for r in runs if r["alone"]["task"] is not None
    ]
    task = (
        "-"
        if not tasks
        else (
            f"{sum(a for a, _ in tasks) / len(tasks):.3g} / "
            f"{sum(s for _, s in tasks) / len(tasks):.3g}"
        )
    )
    return (
        f"| {result['world']} | {result['alone']} | {result['shielded']} | "
        f"{_figure(result['ratio'])} | {_figure(result['worst_seed_ratio'])} | "
        f"{', '.join(map(str, result['harmed_seeds'])) or 'none'} | "
        f"{result['alone_early']} / {result['shielded_early']} | "
        f"{', '.join(map(str, result['early_harmed_seeds'])) or 'none'} | "
        f"{revised / max(steps, 1):.1%} | {_figure(size / revised if revised else None, 3)}"
        f" | {task} |"
    )


def table(paths: list[Path]) -> str:
    """The table of every world in ``paths``, in their order."""
    lines = [HEADER]
    for path in paths:
        lines += [row(result) for result in json.loads(path.read_text())["results"]]
    return "\n".join(lines)


if __name__ == "__main__":
    if len(sys.argv) < 2:
        raise SystemExit(__doc__.splitlines()[0])
    print(table([Path(p) for p in sys.argv[1:]]))  # noqa: T201
