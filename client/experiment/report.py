"""The paper's table and figure from the records of an experiment (section 5, Table 1, Fig. 3)."""

from __future__ import annotations

import json
import os
from collections import defaultdict
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from client.experiment.records import EpisodeRecord, RecordError, read_all, same_course

FAILURES = ("large_distance", "collision")


@dataclass(frozen=True)
class PaperArm:
    """One arm's result in section 5 of the paper (its table and text), over 10 runs x 1500
    episodes; ``percent`` as printed there (12,249 of 15,000 is 81.66%), ``never_fails_after``
    None where the arm failed to the end."""

    name: str
    successes: int
    percent: str
    large_distance: int
    collision: int
    never_fails_after: int | None
    speed_difference: tuple[float, float]


PAPER = {  # by the arm of this project that plays the same part
    "ddpg": PaperArm("DDPG", 12249, "81.6", 1251, 1500, None, (1.9497, 1.8057)),
    "ddpg+shield": PaperArm("DDPG + e-FSM", 14719, "98.1", 76, 205, 68, (2.0460, 1.7800)),
}
PAPER_EPISODES = (10, 1500)


def pooled(records: list[EpisodeRecord]) -> tuple[float | None, float | None]:
    """Mean and variance of |v_ego - v_lead| over all steps of the given episodes."""
    n = np.array([r.speed_diff_n for r in records], dtype=np.float64)
    if n.sum() == 0:
        return None, None
    mean = np.array([r.speed_diff_mean for r in records])
    var = np.array([r.speed_diff_var for r in records])
    total = float((n * mean).sum() / n.sum())
    return total, float((n * (var + mean**2)).sum() / n.sum() - total**2)


def by_hundred(records: list[EpisodeRecord]) -> list[dict[str, Any]]:
    """The outcomes over all runs in episodes 1-100, 101-200, ...: how learning goes on, and
    whether the shield helps early or late."""
    blocks: dict[int, list[EpisodeRecord]] = defaultdict(list)
    for r in records:
        blocks[(r.episode - 1) // 100].append(r)
    rows = []
    for b in sorted(blocks):
        block = blocks[b]
        rows.append(
            {
                "episodes": f"{100 * b + 1}-{max(r.episode for r in block)}",
                "success_rate": float(np.mean([r.outcome == "success" for r in block])),
                "large_distance": sum(r.outcome == "large_distance" for r in block),
                "collision": sum(r.outcome == "collision" for r in block),
                "interventions_per_episode": float(
                    np.mean([sum(r.interventions.values()) for r in block])
                ),
            }
        )
    return rows


LATE = 100  # the per-run table's late phase: each run's last LATE episodes


def per_run(records: list[EpisodeRecord]) -> list[dict[str, Any]]:
    """Each run on its own, over all its episodes and its last ``LATE``: a run that the shield
    keeps in a loop of braking shows here, where the pooled table averages it away."""
    rows = []
    for run in sorted({r.run for r in records}):
        mine = sorted((r for r in records if r.run == run), key=lambda r: r.episode)
        late = mine[-LATE:]
        rows.append(
            {
                "run": run,
                "seed": mine[0].seed,
                "episodes": len(mine),
                "successes": sum(r.outcome == "success" for r in mine),
                "large_distance": sum(r.outcome == "large_distance" for r in mine),
                "collision": sum(r.outcome == "collision" for r in mine),
                "never_fails_after": max(
                    (r.episode for r in mine if r.outcome in FAILURES), default=0
                ),
                "late_episodes": f"{late[0].episode}-{late[-1].episode}",
                "late_success_rate": float(np.mean([r.outcome == "success" for r in late])),
                "late_interventions_per_episode": float(
                    np.mean([sum(r.interventions.values()) for r in late])
                ),
                "n_states": mine[-1].n_states,
            }
        )
    return rows


def summarise(episodes: list[EpisodeRecord]) -> dict[str, Any]:
    """Per arm: the table's counts, the episode after which each run never fails, speed
    differences over successful episodes, and interventions (the actions the shield revised)
    with their share of all steps."""
    by_arm: dict[str, list[EpisodeRecord]] = defaultdict(list)
    for record in episodes:
        by_arm[record.arm].append(record)
    summary: dict[str, Any] = {}
    for arm, records in by_arm.items():
        runs = per_run(records)
        successes = [r for r in records if r.outcome == "success"]
        mean, var = pooled(successes)
        interventions: dict[str, int] = defaultdict(int)
        for r in records:
            for criterion, count in r.interventions.items():
                interventions[criterion] += count
        summary[arm] = {
            "runs": len(runs),
            "seeds": sorted({r.seed for r in records}),
            "episodes": len(records),
            "successes": len(successes),
            "success_rate": len(successes) / len(records),
            "large_distance": sum(r.outcome == "large_distance" for r in records),
            "collision": sum(r.outcome == "collision" for r in records),
            "never_fails_after": max(run["never_fails_after"] for run in runs),
            "never_fails_after_per_run": [run["never_fails_after"] for run in runs],
            "episodes_per_run": [run["episodes"] for run in runs],
            "per_100_episodes": by_hundred(records),
            "per_run": runs,
            "speed_difference_mean": mean,
            "speed_difference_variance": var,
            "interventions": dict(interventions),
            "steps": sum(r.steps for r in records),
            "revised_share": sum(interventions.values()) / max(1, sum(r.steps for r in records)),
            "revisions_in_shadow": sum(r.revisions_would for r in records),
        }
    return summary


def four(x: float | None) -> str:
    """A statistic to four decimals, or "-" where there was nothing to measure."""
    return "-" if x is None else f"{x:.4f}"


def table(summary: dict[str, Any], notes: dict[str, str] | None = None) -> str:
    """The paper's Table 1 per arm, as Markdown; ``notes`` adds a column (for example the
    shield configuration of each row)."""
    extra = ("", "") if notes is None else (" shield configuration |", "---|")
    lines = [
        "| arm | runs | episodes | success | large distance | collision | no failure after "
        f"episode | speed difference mean | variance | interventions (share of steps) |"
        f"{extra[0]}",
        f"|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|{extra[1]}",
    ]
    for arm, s in summary.items():
        note = "" if notes is None else f" {notes[arm]} |"
        lines.append(
            f"| {arm} | {s['runs']} | {s['episodes']} | {s['successes']} "
            f"({100 * s['success_rate']:.1f}%) | {s['large_distance']} | {s['collision']} "
            f"| {s['never_fails_after']} | {four(s['speed_difference_mean'])} "
            f"| {four(s['speed_difference_variance'])} | {sum(s['interventions'].values())} "
            f"({100 * s['revised_share']:.1f}%) |{note}"
        )
    return "\n".join(lines)


def blocks_table(summary: dict[str, Any]) -> str:
    """Success, failures and interventions per block of 100 episodes, a row per arm and block."""
    lines = [
        "| arm | episodes | success | large distance | collision | interventions per episode |",
        "|---|---|---:|---:|---:|---:|",
    ]
    for arm, s in summary.items():
        for b in s["per_100_episodes"]:
            lines.append(
                f"| {arm} | {b['episodes']} | {100 * b['success_rate']:.1f}% "
                f"| {b['large_distance']} | {b['collision']} "
                f"| {b['interventions_per_episode']:.1f} |"
            )
    return "\n".join(lines)


def runs_table(summary: dict[str, Any]) -> str:
    """Each run's outcomes, its last episodes and its model's size at the end."""
    lines = [
        "| arm | run | seed | episodes | success | large distance | collision | no failure "
        "after episode | last episodes | success there | interventions per episode there "
        "| states at the end |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---|---:|---:|---:|",
    ]
    for arm, s in summary.items():
        for r in s["per_run"]:
            states = r["n_states"] if "+" in arm else "-"
            lines.append(
                f"| {arm} | {r['run']} | {r['seed']} | {r['episodes']} "
                f"| {r['successes']} ({100 * r['successes'] / r['episodes']:.1f}%) "
                f"| {r['large_distance']} | {r['collision']} "
                f"| {r['never_fails_after']} | {r['late_episodes']} "
                f"| {100 * r['late_success_rate']:.1f}% "
                f"| {r['late_interventions_per_episode']:.1f} | {states} |"
            )
    return "\n".join(lines)


def paper_table(summary: dict[str, Any]) -> str | None:
    """This experiment's DDPG arms beside the paper's result, or None without such arms."""
    arms = [arm for arm in PAPER if arm in summary]
    if not arms:
        return None
    lines = [
        "| | episodes | success | large distance | collision | no failure after episode "
        "| speed difference mean / variance |",
        "|---|---:|---:|---:|---:|---:|---|",
    ]
    runs, each = PAPER_EPISODES
    for arm in arms:
        p = PAPER[arm]
        after = "-" if p.never_fails_after is None else p.never_fails_after
        mean, var = p.speed_difference
        lines.append(
            f"| paper: {p.name} | {runs} x {each} | {p.successes:,} ({p.percent}%) "
            f"| {p.large_distance:,} | {p.collision:,} | {after} "
            f"| {mean:.4f} / {var:.4f} |"
        )
    for arm in arms:
        s = summary[arm]
        counts = set(s["episodes_per_run"])
        episodes = (
            f"{s['runs']} x {counts.pop()}"
            if len(counts) == 1
            else f"{s['runs']} runs, {s['episodes']:,}"
        )
        speed = f"{four(s['speed_difference_mean'])} / {four(s['speed_difference_variance'])}"
        lines.append(
            f"| this: {arm} | {episodes} | {s['successes']:,} "
            f"({100 * s['success_rate']:.1f}%) | {s['large_distance']:,} "
            f"| {s['collision']:,} | {s['never_fails_after']} | {speed} |"
        )
    return "\n".join(lines)


def labels(directories: list[Path]) -> list[str]:
    """A row label per experiment: its folder's name, or where names repeat (the same
    experiment on other seeds) its path below the folders' common parent."""
    names = [d.name for d in directories]
    if len(set(names)) == len(names):
        return names
    resolved = [d.resolve() for d in directories]
    if len(set(resolved)) < len(resolved):
        raise RecordError("an experiment is given twice")
    common = Path(os.path.commonpath(resolved))
    return [str(d.relative_to(common)) for d in resolved]


def side_by_side(summary: dict[str, Any]) -> str:
    """The rows of ``summary`` per block of 100 episodes, side by side in each cell: how
    experiments differ as learning goes on, which the pooled table averages away."""
    names = list(summary)
    blocks = [
        {int(b["episodes"].split("-")[0]): b for b in s["per_100_episodes"]}
        for s in summary.values()
    ]
    columns = (
        ("success_rate", "{:.1%}"),
        ("large_distance", "{}"),
        ("collision", "{}"),
        ("interventions_per_episode", "{:.1f}"),
    )
    lines = [
        f"Per block of 100 episodes, each cell {' / '.join(names)}:",
        "",
        "| episodes | success | large distance | collision | interventions per episode |",
        "|---|---|---|---|---|",
    ]
    for start in sorted(set().union(*blocks)):
        cells = [b.get(start) for b in blocks]
        spans = " / ".join(dict.fromkeys(c["episodes"] for c in cells if c is not None))
        values = [
            " / ".join("-" if c is None else form.format(c[key]) for c in cells)
            for key, form in columns
        ]
        lines.append(f"| {spans} | {' | '.join(values)} |")
    return "\n".join(lines)


def parting(first: list[EpisodeRecord], other: list[EpisodeRecord]) -> dict[tuple[str, int], str]:
    """Per run of ``first`` (arm, run), where the same run in ``other`` goes another way: the
    first episode of another course (:func:`~client.experiment.records.same_course`), with
    "(rounding from E)" where the records already differed in anything but the wall time
    from an earlier episode E (another machine's arithmetic); "none in N" where the two
    agree on all N episodes both hold, "other seed" where the two were seeded apart (not the
    same run), "-" where ``other`` lacks the run. Paired ablations share their seeds, so a
    switch shows first where its run parts."""

    def runs(episodes: list[EpisodeRecord]) -> dict[tuple[str, int], list[EpisodeRecord]]:
        grouped: dict[tuple[str, int], list[EpisodeRecord]] = defaultdict(list)
        for r in sorted(episodes, key=lambda r: (r.arm, r.run, r.episode)):
            grouped[(r.arm, r.run)].append(replace(r, wall_s=0.0))
        return grouped

    theirs = runs(other)
    where: dict[tuple[str, int], str] = {}
    for key, mine in runs(first).items():
        paired = theirs.get(key)
        if not paired:
            where[key] = "-"
        elif paired[0].seed != mine[0].seed:
            where[key] = "other seed"
        else:
            both = list(zip(mine, paired, strict=False))  # as far as the shorter run went
            course = next((a.episode for a, b in both if not same_course(a, b)), None)
            digits = next((a.episode for a, b in both if a != b), None)
            where[key] = f"none in {len(both)}" if course is None else str(course)
            if digits is not None and digits != course:
                where[key] += f" (rounding from {digits})"
    return where


def partings_table(names: list[str], episodes: list[list[EpisodeRecord]]) -> str:
    """Where each run of the later experiments parts from the same run of the first."""
    columns = [parting(episodes[0], other) for other in episodes[1:]]
    lines = [
        f"Where each run parts from the same run of {names[0]} (the first episode of "
        "another length, outcome or revisions):",
        "",
        f"| arm | run | {' | '.join(names[1:])} |",
        "|---|---:|" + "---:|" * len(columns),
    ]
    for arm, run in columns[0]:
        lines.append(f"| {arm} | {run} | {' | '.join(c[(arm, run)] for c in columns)} |")
    return "\n".join(lines)


def compare(
    directories: list[Path], limit: int | None = None, blocks: bool = False, partings: bool = False
) -> str:
    """One table over several experiments (ablations): a row per directory and arm, with the
    shield configuration each was run with; of each run's first ``limit`` episodes, if
    given; with ``blocks``, also the rows per block of 100 episodes side by side; with
    ``partings``, where each run of the later experiments parts from the first's."""
    summary: dict[str, Any] = {}
    notes: dict[str, str] = {}
    names = labels(directories)
    every: list[list[EpisodeRecord]] = []
    for directory, name in zip(directories, names, strict=True):
        headers, episodes = read_all(directory)
        if limit is not None:
            episodes = first_episodes(episodes, limit)
        every.append(episodes)
        overrides = json.dumps(headers[0]["config"]["shield_config"], separators=(",", ":"))
        for arm, row in summarise(episodes).items():
            label = f"{name}: {arm}"
            summary[label] = row
            notes[label] = f"`{overrides}`" if "+" in arm else "-"
    parts = [table(summary, notes)]
    if blocks:
        parts.append(side_by_side(summary))
    if partings:
        if len(directories) < 2:
            raise RecordError("where runs part needs two experiments or more")
        parts.append(partings_table(names, every))
    return "\n\n".join(parts)


def figure(episodes: list[EpisodeRecord], path: Path) -> None:
    """Steps per episode (mean and range over runs) and interventions per episode, per arm."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (steps_ax, revisions_ax) = plt.subplots(1, 2, figsize=(12, 4.2))
    for index, arm in enumerate(sorted({r.arm for r in episodes})):
        colour = f"C{index}"
        rows = [r for r in episodes if r.arm == arm]
        runs = sorted({r.run for r in rows})
        length = max(r.episode for r in rows)
        steps = np.full((len(runs), length), np.nan)
        revisions = np.full((len(runs), length), np.nan)
        for r in rows:
            steps[runs.index(r.run), r.episode - 1] = r.steps
            revisions[runs.index(r.run), r.episode - 1] = sum(r.interventions.values())
        x = np.arange(1, length + 1)
        steps_ax.plot(x, np.nanmean(steps, axis=0), label=arm, linewidth=1, color=colour)
        steps_ax.fill_between(
            x, np.nanmin(steps, axis=0), np.nanmax(steps, axis=0), color=colour, alpha=0.15
        )
        if np.nansum(revisions) > 0:
            revisions_ax.plot(
                x, np.nanmean(revisions, axis=0), label=arm, linewidth=1, color=colour
            )
    steps_ax.set(
        xlabel="episode",
        ylabel="steps (800 = success)",
        title="Steps per episode: mean, range over runs",
    )
    revisions_ax.set(
        xlabel="episode",
        ylabel="revised actions",
        title="Interventions per episode (mean over runs)",
    )
    for ax in (steps_ax, revisions_ax):
        ax.grid(alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def first_episodes(episodes: list[EpisodeRecord], limit: int) -> list[EpisodeRecord]:
    """Each run's first ``limit`` episodes: experiments stopped at different points (every
    run of an arm at its own pace) compared on equal footing. Every run must have reached
    ``limit``."""
    counts: dict[tuple[str, int], int] = defaultdict(int)
    for r in episodes:
        counts[(r.arm, r.run)] += 1
    (arm, run), fewest = min(
        counts.items(), key=lambda item: (item[1], item[0]), default=(("", 0), limit)
    )
    if fewest < limit:
        raise RecordError(
            f"run {run} of {arm} has only {fewest} episodes; --episodes must be at most {fewest}"
        )
    return [r for r in episodes if r.episode <= limit]


def write(directory: Path, limit: int | None = None) -> tuple[str, dict[str, Any]]:
    """summary.json, table.md and figure.png next to the records (of each run's first
    ``limit`` episodes, if given); returns the table."""
    headers, episodes = read_all(directory)
    if not episodes:
        raise RecordError(f"{directory}: the record files hold no episode yet")
    if limit is not None:
        episodes = first_episodes(episodes, limit)
    summary = summarise(episodes)
    summary_doc = {
        "arms": summary,
        "config": headers[0]["config"],
        "versions": headers[0]["versions"],
        "episode_limit": limit,
    }
    (directory / "summary.json").write_text(json.dumps(summary_doc, indent=2))
    text = (
        f"{table(summary)}\n\nPer block of 100 episodes, all runs together:\n\n"
        f"{blocks_table(summary)}\n\nPer run (its last {LATE} episodes on the right):\n\n"
        f"{runs_table(summary)}"
    )
    beside = paper_table(summary)
    if beside is not None:
        text += f"\n\nBeside the paper's result (its section 5):\n\n{beside}"
    (directory / "table.md").write_text(text + "\n")
    figure(episodes, directory / "figure.png")
    return text, summary
