"""Step traces of shielded runs, and what they say about the shield (``run --trace``, ``trace``).

The episode records count revisions; a trace keeps every decision with the observation it was
made on, so that one can ask where the shield revises and whether it saw each failure coming.
One gzipped JSON Lines file per shielded run, ``traces/<arm>__runNN.jsonl.gz``, written anew
whenever the run is played (a resumed run replays from its start, so its trace is whole).
"""

from __future__ import annotations

import gzip
import json
from collections import Counter, defaultdict
from collections.abc import Callable
from pathlib import Path
from typing import IO, Any

import numpy as np

from client.experiment.records import RecordError, read_all

HEADWAY_BANDS = ((0, 10), (10, 20), (20, 40), (40, 80), (80, 150), (150, None))  # [m]
LOOKBACK = 10  # steps before a failure that count as "saw it coming" (2.5 s at dt 0.25 s)
EXAMPLES = 2  # failure episodes shown step by step, per failure kind and arm
REASON_BLOCK = 50  # episodes per row of the table of decisions by reason
ACTIVE = ("pass", "revised_safety", "revised_speed")  # the reviser was on for this decision
NEAR = 0.05  # [m/s^2] a revision applied this close to the proposal changed next to nothing


def path_for(directory: Path, arm: str, run: int) -> Path:
    return directory / "traces" / f"{arm.replace('+', '_')}__run{run:02d}.jsonl.gz"


class TraceWriter:
    """Writes one run's decisions as they happen."""

    def __init__(self, directory: Path, arm: str, run: int) -> None:
        path = path_for(directory, arm, run)
        path.parent.mkdir(parents=True, exist_ok=True)
        self._file: IO[str] = gzip.open(path, "wt", encoding="utf-8")

    def recorder(self, episode: int) -> Callable[[float, dict[str, Any]], None]:
        """What :func:`client.experiment.runner.play` calls after each step of ``episode``."""

        def record(proposed: float, info: dict[str, Any]) -> None:
            decision = info.get("shield")
            if decision is not None:
                self.add(episode, info["shield_observation"], proposed, decision)

        return record

    def add(self, episode: int, z: list[float], proposed: float, d: dict[str, Any]) -> None:
        """One step: its observation, the proposal and the decision record (as data)."""
        row = {
            "e": episode,
            "z": [round(v, 2) for v in z],
            "p": round(proposed, 3),
            "a": None if d["action"] is None else round(d["action"], 3),
            "r": d["reason"],
            "v": d["verdict"],
            "risk": {k: round(v, 4) for k, v in d["risk"].items()},
            "t": None if d["threshold"] is None else round(d["threshold"], 4),
            "s": d["state"],
            "n": d["n_states"],
        }
        self._file.write(json.dumps(row, separators=(",", ":")) + "\n")

    def close(self) -> None:
        self._file.close()


def read(path: Path) -> list[dict[str, Any]]:
    try:
        with gzip.open(path, "rt", encoding="utf-8") as handle:
            return [json.loads(line) for line in handle]
    except (OSError, EOFError, ValueError) as error:
        raise RecordError(f"{path}: damaged trace ({error}); run the experiment again") from error


def analyse(directory: Path) -> str:
    """Markdown, per arm: decisions by reason over the episodes, where the shield revises (by
    headway), whether it revised before each failure and how far its revisions moved the
    action, which states the failures came from, and the last steps of a few failures."""
    paths = sorted((directory / "traces").glob("*.jsonl.gz"))
    if not paths:
        raise RecordError(f"{directory}: no traces; run the experiment with --trace")
    _, records = read_all(directory)
    outcomes = {(r.arm, r.run, r.episode): r.outcome for r in records}
    by_arm: dict[str, list[list[dict[str, Any]]]] = defaultdict(list)
    for path in paths:
        arm, run = path.name.removesuffix(".jsonl.gz").rsplit("__run", 1)
        arm = arm.replace("_", "+")
        steps_of: dict[int, list[dict[str, Any]]] = defaultdict(list)
        for row in read(path):
            steps_of[row["e"]].append(row)
        for e, steps in sorted(steps_of.items()):
            outcome = outcomes.get((arm, int(run), e))
            if outcome is None:
                raise RecordError(f"{path}: episode {e} has no record")
            by_arm[arm].append([{**s, "outcome": outcome, "run": int(run)} for s in steps])
    parts = []
    for arm, episodes in by_arm.items():
        active = [e for e in episodes if e[0]["r"] in ACTIVE]
        parts.append(
            f"## {arm}: {len(active)} episodes with the reviser on (of {len(episodes)} traced)\n"
        )
        criteria = list(episodes[0][0]["risk"])  # every decision names every criterion
        parts.append(_reasons(episodes))
        parts.append(_by_headway([s for e in active for s in e], criteria))
        parts.append(_before_failures(active, criteria))
        if not arm.endswith("+shadow"):  # a shadow arm applies the proposals
            parts.append(_revision_sizes(active, criteria))
        parts.append(_failure_states(episodes, criteria))
        parts.append(_examples(active, criteria))
    return "\n".join(parts)


def _reasons(episodes: list[list[dict[str, Any]]]) -> str:
    """Decisions by reason per block of episodes: when the reviser acts, and when it cannot
    (``cold_start``: no state flagged)."""
    blocks: dict[int, Counter[str]] = defaultdict(Counter)
    for e in episodes:
        blocks[(e[0]["e"] - 1) // REASON_BLOCK].update(s["r"] for s in e)
    reasons = sorted({r for c in blocks.values() for r in c})
    lines = ["| episodes | " + " | ".join(reasons) + " |", "|---|" + "---:|" * len(reasons)]
    for b, counts in sorted(blocks.items()):
        label = f"{REASON_BLOCK * b + 1}-{REASON_BLOCK * (b + 1)}"
        lines.append(f"| {label} | " + " | ".join(str(counts[r]) for r in reasons) + " |")
    title = "Decisions by reason (all runs; cold_start: no state flagged):"
    return title + "\n\n" + "\n".join(lines) + "\n"


def _by_headway(steps: list[dict[str, Any]], criteria: list[str]) -> str:
    head = (
        "| headway (m) | steps | "
        + " | ".join(f"revised against {c} | predicted {c} risk p50 / p90" for c in criteria)
        + " |"
    )
    lines = [head, "|---|---:|" + "---:|---:|" * len(criteria)]
    for low, high in HEADWAY_BANDS:
        band = [s for s in steps if s["z"][1] >= low and (high is None or s["z"][1] < high)]
        if not band:
            continue
        cells = []
        for c in criteria:
            revised = sum(s["v"] == c and s["r"].startswith("revised") for s in band)
            p50, p90 = np.percentile([s["risk"][c] for s in band], [50, 90])
            cells.append(f"{100 * revised / len(band):.1f}% | {p50:.3f} / {p90:.3f}")
        label = f"{low}-{high}" if high is not None else f"{low}+"
        lines.append(f"| {label} | {len(band)} | " + " | ".join(cells) + " |")
    return "Where the shield revises:\n\n" + "\n".join(lines) + "\n"


def _before_failures(episodes: list[list[dict[str, Any]]], criteria: list[str]) -> str:
    lines = [
        f"| failure | episodes | revised against it in the last {LOOKBACK} steps | "
        f"its predicted risk at or above the threshold there | median of its highest "
        f"predicted risk there |",
        "|---|---:|---:|---:|---:|",
    ]
    for criterion in criteria:
        failed = [e for e in episodes if e[-1]["outcome"] == criterion]
        if not failed:
            continue
        tails = [e[-LOOKBACK:] for e in failed]
        revised = sum(
            any(s["v"] == criterion and s["r"].startswith("revised") for s in t) for t in tails
        )
        above = sum(
            any(s["t"] is not None and s["risk"][criterion] >= s["t"] for s in t) for t in tails
        )
        peak = float(np.median([max(s["risk"][criterion] for s in t) for t in tails]))
        n = len(failed)
        lines.append(
            f"| {criterion} | {n} | {revised} ({100 * revised / n:.0f}%) | "
            f"{above} ({100 * above / n:.0f}%) | {peak:.3f} |"
        )
    return "Before each failure:\n\n" + "\n".join(lines) + "\n"


def _revision_sizes(episodes: list[list[dict[str, Any]]], criteria: list[str]) -> str:
    """How far the applied revisions moved the action from the proposal, over all decisions
    and in the last steps before each failure: the revision noise, cut at the proposal by
    one-sided revisions, can leave a revision next to the proposal."""
    lines = [
        "| revisions against | where | revisions | median of applied - proposed (m/s^2) | "
        f"applied within {NEAR} m/s^2 of the proposal |",
        "|---|---|---:|---:|---:|",
    ]
    for criterion in criteria:
        tails = [e[-LOOKBACK:] for e in episodes if e[-1]["outcome"] == criterion]
        for where, steps in (
            ("every step", [s for e in episodes for s in e]),
            (f"the last {LOOKBACK} steps before a {criterion}", [s for t in tails for s in t]),
        ):
            moved = [
                s["a"] - s["p"]
                for s in steps
                if s["v"] == criterion and s["r"].startswith("revised")
            ]
            if not moved:
                continue
            near = sum(abs(m) <= NEAR for m in moved)
            lines.append(
                f"| {criterion} | {where} | {len(moved)} | "
                f"{float(np.median(moved)):+.3f} | "
                f"{near} ({100 * near / len(moved):.0f}%) |"
            )
    return "How far the revisions moved the action:\n\n" + "\n".join(lines) + "\n"


def _failure_states(episodes: list[list[dict[str, Any]]], criteria: list[str]) -> str:
    """Per run, the states the failures came from (the state of each failed episode's last
    decision) against how often each was recognised: a state whose failures are a small share
    of the entries into it is not flagged by count-based flags."""
    recognised: Counter[tuple[int, int]] = Counter((s["run"], s["s"]) for e in episodes for s in e)
    failures: dict[tuple[int, int], Counter[str]] = defaultdict(Counter)
    for e in episodes:
        if e[-1]["outcome"] in criteria:
            failures[(e[-1]["run"], e[-1]["s"])][e[-1]["outcome"]] += 1
    head = "| run | state | decisions in it | " + " | ".join(criteria) + " | revised in the run |"
    lines = [head, "|---:|---:|---:|" + "---:|" * len(criteria) + "---:|"]
    revised = Counter(s["run"] for e in episodes for s in e if s["r"].startswith("revised"))
    for run, state in sorted(failures):
        counts = failures[(run, state)]
        lines.append(
            f"| {run} | {state} | {recognised[(run, state)]} | "
            + " | ".join(str(counts[c]) for c in criteria)
            + f" | {revised[run]} |"
        )
    return (
        "Where the failures came from (the state of each failed episode's last decision):\n\n"
        + "\n".join(lines)
        + "\n"
    )


def _examples(episodes: list[list[dict[str, Any]]], criteria: list[str]) -> str:
    out = []
    for criterion in criteria:
        for e in [e for e in episodes if e[-1]["outcome"] == criterion][:EXAMPLES]:
            out.append(f"The last steps of episode {e[0]['e']} ({criterion}):\n")
            out.append(
                "| v_ego | headway | v_lead | proposed | applied | decision | "
                f"{criterion} risk | threshold | state |"
            )
            out.append("|---:|---:|---:|---:|---:|---|---:|---:|---:|")
            for s in e[-LOOKBACK:]:
                v, h, vl = s["z"]
                threshold = "-" if s["t"] is None else f"{s['t']:.3f}"
                out.append(
                    f"| {v:.1f} | {h:.1f} | {vl:.1f} | {s['p']:+.2f} | {s['a']:+.2f} | "
                    f"{s['r']} | {s['risk'][criterion]:.3f} | {threshold} | "
                    f"{s['s']} of {s['n']} |"
                )
            out.append("")
    return "\n".join(out)
