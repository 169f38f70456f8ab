"""Per-episode records: one JSON Lines file per (arm, run), appended as episodes finish.

The first line of every file is a header with the experiment's configuration, the shield's
whole configuration as the run used it (shielded arms), the versions and the run's seed;
every other line is one :class:`EpisodeRecord`. Finished experiments may be kept gzipped
(``*.jsonl.gz``, as the committed results are); they read the same.
"""

from __future__ import annotations

import fcntl
import gzip
import json
import os
import zlib
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import IO, Any

from app.core import ShieldConfig, ShieldError
from client.sim.car_following import RewardConfig


@dataclass(frozen=True)
class EpisodeRecord:
    """What one episode did."""

    arm: str
    run: int
    episode: int  # 1-based
    seed: int  # the run's seed
    steps: int
    outcome: str  # success, collision or large_distance
    interventions: dict[str, int] = field(default_factory=dict)
    revisions_would: int = 0  # shadow mode: decisions that would have been revised
    speed_diff_n: int = 0  # |v_ego - v_lead| over the episode's steps: count, mean, variance
    speed_diff_mean: float = 0.0
    speed_diff_var: float = 0.0
    episode_return: float = 0.0
    n_states: int = 0
    wall_s: float = 0.0


def same_course(a: EpisodeRecord, b: EpisodeRecord) -> bool:
    """Whether two records of an episode tell the same course: its length, its outcome and the
    revisions on the way. Speeds and returns can differ in their last digits between
    machines whose arithmetic rounds differently while the episode goes the same way."""
    return (a.steps, a.outcome, a.interventions) == (b.steps, b.outcome, b.interventions)


class RecordError(Exception):
    """A record file is missing, damaged or from another configuration."""


def path_for(directory: Path, arm: str, run: int) -> Path:
    return directory / "records" / f"{arm.replace('+', '_')}__run{run:02d}.jsonl"


def claim(path: Path) -> IO[bytes]:
    """Hold the run's file exclusively until the returned handle is closed, so that two
    processes never append to one run (a second gets :class:`RecordError`)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    handle = open(path, "ab")
    try:
        fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        handle.close()
        raise RecordError(
            f"{path}: another process is writing this run; stop it or wait for it"
        ) from None
    return handle


def release(handle: IO[bytes], path: Path) -> None:
    """Give up a run's claim: a file the claim left empty goes too, so that a refused run, or
    a finished one read from its archive, leaves its folder as it was."""
    if path.exists() and path.stat().st_size == 0:
        path.unlink()
    handle.close()


def start(path: Path, header: dict[str, Any], episodes: int) -> list[EpisodeRecord]:
    """Open a run of ``episodes`` episodes: create its file with the header, or read the
    episodes it already holds.

    An existing file must carry the same ``identity`` (the configuration less where the
    shield runs and how it is reached, which change no result), the same resolved reward
    constants and, where both headers have it, the same resolved shield configuration (the
    overrides alone do not show a change of the defaults), else :class:`RecordError`. A run
    kept gzipped is read where it is when it is finished, and unpacked to go on plain when it
    is not.
    """
    packed = path.with_name(path.name + ".gz")
    empty = not path.exists() or path.stat().st_size == 0
    if empty and not packed.exists():
        path.parent.mkdir(parents=True, exist_ok=True)
        with open(path, "w") as f:
            f.write(json.dumps({"header": header}) + "\n")
        return []
    source = packed if empty else path
    if source is path:
        data = path.read_bytes()
        if not data.endswith(b"\n"):  # a torn last line (a crash mid-write): cut it off
            with open(path, "r+b") as f:
                f.truncate(data.rfind(b"\n") + 1)
    existing_header, records = read(source)  # a damaged archive is refused untouched
    if existing_header.get("identity") != header.get("identity"):
        raise RecordError(f"{source}: written with another configuration; use another --out")
    before, now = existing_header.get("shield"), header.get("shield")
    if before is not None and now is not None and not same_shield(before, now):
        raise RecordError(
            f"{source}: written with another shield configuration (the defaults "
            f"have changed since); remove it or use another --out"
        )
    if "reward" in header and resolved_reward(existing_header) != header["reward"]:
        raise RecordError(
            f"{source}: written with other reward constants (the defaults have "
            f"changed since); remove it or use another --out"
        )
    if source is packed and len(records) < episodes:
        with open(path, "wb") as f:
            f.write(gzip.decompress(packed.read_bytes()))
            f.flush()
            os.fsync(f.fileno())
        packed.unlink()
    return records


def resolved_reward(header: dict[str, Any]) -> dict[str, Any]:
    """The reward constants a run used: its header's, or for a header written before headers
    carried them, its overrides over the defaults of its time (the failure penalty did not
    exist then: 0)."""
    if "reward" in header:
        resolved: dict[str, Any] = header["reward"]
        return resolved
    return asdict(RewardConfig(**{"failure_penalty": 0.0, **header["config"].get("reward", {})}))


def same_shield(before: dict[str, Any], now: dict[str, Any]) -> bool:
    """Whether two resolved shield configurations decide alike: a field added since the
    first was written counts at the value it was added with, which keeps the behaviour of
    its time."""
    try:
        return ShieldConfig.from_stored(before) == ShieldConfig.from_stored(now)
    except ShieldError:  # a field that no longer exists
        return False


def append(path: Path, record: EpisodeRecord) -> None:
    """Add one episode, durably (flush and fsync)."""
    with open(path, "a") as f:
        f.write(json.dumps(asdict(record)) + "\n")
        f.flush()
        os.fsync(f.fileno())


def read(path: Path) -> tuple[dict[str, Any], list[EpisodeRecord]]:
    """The header and the episodes of one file, plain or gzipped; a torn last line is
    ignored."""
    try:
        data = path.read_bytes()
        lines = (gzip.decompress(data) if path.suffix == ".gz" else data).decode().split("\n")
    except OSError as error:
        raise RecordError(f"{path}: {error.strerror or error}") from error
    except (EOFError, zlib.error, UnicodeDecodeError) as error:
        raise RecordError(f"{path}: damaged ({error})") from error
    try:
        header = json.loads(lines[0])["header"]
    except (ValueError, KeyError, TypeError) as error:
        raise RecordError(f"{path}: no header line; not a record file") from error
    records = []
    for number, line in enumerate(lines[1:], start=2):
        if not line:
            continue
        try:
            records.append(EpisodeRecord(**json.loads(line)))
        except (ValueError, TypeError) as error:
            if number == len(lines):  # an unterminated last line: a crash mid-write
                break
            raise RecordError(f"{path}: line {number} is damaged") from error
    return header, records


def read_all(directory: Path) -> tuple[list[dict[str, Any]], list[EpisodeRecord]]:
    """Every header and episode under ``directory/records``."""
    files = sorted(
        [*(directory / "records").glob("*.jsonl"), *(directory / "records").glob("*.jsonl.gz")]
    )
    if not files:
        raise RecordError(f"{directory}: no record files under records/")
    runs = [path.name.removesuffix(".gz") for path in files]
    if len(set(runs)) < len(runs):
        raise RecordError(f"{directory}: a run is there both plain and gzipped; keep one")
    headers, episodes = [], []
    for path in files:
        header, records = read(path)
        headers.append(header)
        episodes.extend(records)
    return headers, episodes
