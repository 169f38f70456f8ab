"""The files of one model: configuration, the last snapshot, and a journal of accepted steps.

``DATA/models/<name>/`` holds ``config.json``, ``snapshot.npz`` and ``journal.log``. Every
accepted learning request is appended to the journal *before* the model applies it (write-ahead),
one line per request: ``<crc32 hex> <json>``. A snapshot is taken in two moves: the journal is
rotated to ``journal.1.log`` when the model's state is copied (under the model's lock), and the
snapshot is written (temporary file, fsync, rename) and ``journal.1.log`` removed afterwards,
while the model goes on learning into a new journal. Because learning is deterministic, the
snapshot plus the records of both journals after its version rebuild the model exactly, at
every moment in between.

Reading the journals back (:meth:`ModelStore.scan`) finds the first line that is not a whole
record (torn by a crash mid-write, failing its checksum, garbage) and says whether any readable
record follows it. Damage that nothing readable follows is a damaged tail: the registry repairs
it as Redis repairs a truncated append-only file, cutting the journal after its last good
record (:meth:`ModelStore.cut`, the cut bytes kept beside it) and taking a snapshot, so that new
records never land after the damaged bytes. Damage that readable records follow is not a torn
write: the model is set aside with its files untouched.
"""

from __future__ import annotations

import json
import logging
import os
import shutil
import threading
import zlib
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Literal

log = logging.getLogger("app.storage")

Fsync = Literal["always", "interval", "never"]


def write_atomic(path: Path, data: bytes) -> None:
    """Replace ``path`` with ``data`` so that a crash leaves the old or the new file, whole."""
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "wb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)
    sync_directory(path.parent)


def sync_directory(directory: Path) -> None:
    """Make a rename or a new file in ``directory`` durable."""
    fd = os.open(directory, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


class ModelStore:
    """Durable storage of one model."""

    def __init__(self, directory: Path, fsync: Fsync) -> None:
        self.directory = directory
        self.fsync = fsync
        self._journal: Any = None
        self._dirty = False
        self._lock = threading.Lock()  # the journal file against the interval syncer

    @property
    def config_path(self) -> Path:
        return self.directory / "config.json"

    @property
    def snapshot_path(self) -> Path:
        return self.directory / "snapshot.npz"

    @property
    def journal_path(self) -> Path:
        return self.directory / "journal.log"

    @property
    def rotated_path(self) -> Path:
        """The records a snapshot being written will cover."""
        return self.directory / "journal.1.log"

    def create(self, config: dict[str, Any]) -> None:
        """Start the files of a new model."""
        self.directory.mkdir(parents=True, exist_ok=True)
        write_atomic(self.config_path, json.dumps(config, indent=2).encode())
        sync_directory(self.directory.parent)

    def append(self, record: dict[str, Any]) -> None:
        """Write one journal record; durable at once under ``fsync=always``."""
        payload = json.dumps(record, separators=(",", ":"), allow_nan=False)
        line = f"{zlib.crc32(payload.encode()):08x} {payload}\n".encode()
        with self._lock:
            if self._journal is None:
                self._journal = open(self.journal_path, "ab")
            self._journal.write(line)
            self._journal.flush()  # in the OS: survives a crash of this process
            if self.fsync == "always":
                os.fsync(self._journal.fileno())
            else:
                self._dirty = True

    def sync(self) -> None:
        """Flush the journal to the disk if it changed (the ``interval`` policy calls this)."""
        with self._lock:
            if self._dirty and self._journal is not None:
                os.fsync(self._journal.fileno())
                self._dirty = False

    def rotate(self) -> None:
        """Start a new, empty journal; the records so far join ``journal.1.log`` until
        :meth:`write_snapshot` stores the snapshot that covers them. ``journal.log`` exists at
        every moment (a crash in between leaves its records in both files, and the replay
        skips the second copy by version), so a missing journal is always damage."""
        with self._lock:
            if self._journal is not None:
                self._journal.flush()
                os.fsync(self._journal.fileno())
                self._journal.close()
                self._journal = None
                self._dirty = False
            if self.journal_path.exists():
                if self.rotated_path.exists():  # a snapshot that was never written
                    with open(self.rotated_path, "ab") as f:
                        f.write(self.journal_path.read_bytes())
                        f.flush()
                        os.fsync(f.fileno())
                else:
                    os.link(self.journal_path, self.rotated_path)
                    sync_directory(self.directory)
            write_atomic(self.journal_path, b"")

    def write_snapshot(self, blob: bytes) -> None:
        """Store a snapshot that covers every record rotated before it."""
        write_atomic(self.snapshot_path, blob)
        self.rotated_path.unlink(missing_ok=True)
        sync_directory(self.directory)

    def read_snapshot(self) -> bytes | None:
        """The last snapshot, if one was taken."""
        return self.snapshot_path.read_bytes() if self.snapshot_path.exists() else None

    def read_config(self) -> dict[str, Any]:
        result: dict[str, Any] = json.loads(self.config_path.read_text())
        return result

    def scan(self) -> tuple[list[dict[str, Any]], Damage | None]:
        """The journal records in order, the rotated ones first, up to the first damaged
        line; and that damage, if any."""
        records: list[dict[str, Any]] = []
        paths = [p for p in (self.rotated_path, self.journal_path) if p.exists()]
        for i, path in enumerate(paths):
            data = path.read_bytes()
            start = 0
            for number, line in enumerate(data.split(b"\n"), start=1):
                end = start + len(line)
                whole = end < len(data)  # a line without its newline is torn
                record = _parse(line) if whole else None
                if record is None:
                    if not line and not whole:
                        break  # the end of the file
                    later = data[end + 1 :].split(b"\n") if whole else []
                    later += [ln for p in paths[i + 1 :] for ln in p.read_bytes().split(b"\n")]
                    cuts = [(path, start)] + [(p, 0) for p in paths[i + 1 :]]
                    at_tail = not any(_parse(ln) is not None for ln in later)
                    return records, Damage(
                        path, number, start, len(data) - start, at_tail, tuple(cuts)
                    )
                records.append(record)
                start = end + 1
        return records, None

    def cut(self, damage: Damage) -> list[Path]:
        """Cut the journals at ``damage`` (a damaged tail): each file ends at its last good
        record, the bytes cut from it are kept in ``<file>.damaged-<UTC time>``; all durable
        before this returns. The copies written."""
        stamp = datetime.now(UTC).strftime("%Y%m%dT%H%M%S.%fZ")
        kept = []
        for path, offset in damage.cuts:
            with open(path, "r+b") as f:
                f.seek(offset)
                tail = f.read()
                if tail:
                    copy = path.with_name(f"{path.name}.damaged-{stamp}")
                    write_atomic(copy, tail)
                    kept.append(copy)
                f.truncate(offset)
                f.flush()
                os.fsync(f.fileno())
        sync_directory(self.directory)
        return kept

    def close(self) -> None:
        """Flush and close the journal."""
        self.sync()
        with self._lock:
            if self._journal is not None:
                self._journal.close()
                self._journal = None

    def remove(self) -> None:
        """Delete every file of the model."""
        self.close()
        shutil.rmtree(self.directory, ignore_errors=True)


@dataclass(frozen=True)
class Damage:
    """Where the journals stop being readable: line ``line`` of ``path``, ``offset`` bytes
    into it, ``size`` bytes to its end; ``at_tail`` when no readable record follows (in this
    file or the next); ``cuts``: each file with the offset its good records end at."""

    path: Path
    line: int
    offset: int
    size: int
    at_tail: bool
    cuts: tuple[tuple[Path, int], ...]

    def describe(self) -> str:
        return (
            f"{self.path.name} line {self.line} ({self.size} bytes from offset "
            f"{self.offset} to the end of the file) is not a whole journal record"
        )


def _parse(line: bytes) -> dict[str, Any] | None:
    crc, _, payload = line.partition(b" ")
    try:
        if int(crc, 16) != zlib.crc32(payload):
            return None
        record: dict[str, Any] = json.loads(payload)
        return record
    except ValueError:
        return None
