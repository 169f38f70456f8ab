"""A journal damaged at its tail is repaired without loss; damage elsewhere sets the model
aside (issue #69, findings 1 and 7): after either, no step acknowledged later is lost."""

from __future__ import annotations

import logging
import random
from collections.abc import Callable
from pathlib import Path

import pytest

from app.core import ShieldConfig
from app.service.registry import ModelQuarantined, ModelRegistry, Step
from tests.utils import random_stream


def feed(registry: ModelRegistry, name: str, seed: int, n: int) -> None:
    for z, a, done in random_stream(seed, n):
        registry.step(name, Step(z, None if done else a, done=done))


def reopen(data: Path, **kwargs: object) -> ModelRegistry:
    """A registry over ``data``; the one before it is abandoned unclosed, as by a kill -9
    (fsync=always: every acknowledged step is on the disk)."""
    registry = ModelRegistry(data, fsync="always", **kwargs)  # type: ignore[arg-type]
    registry.open()
    return registry


def version(registry: ModelRegistry, name: str = "m") -> int:
    return registry.get(name).shield.counters.model_version


def cut_40_bytes(journal: Path) -> None:
    data = journal.read_bytes()
    journal.write_bytes(data[:-40])


def append_garbage(journal: Path) -> None:
    with open(journal, "ab") as f:
        f.write(random.Random(1).randbytes(64).replace(b"\n", b"x") + b"\n")


def flip_a_bit_of_the_last_record(journal: Path) -> None:
    data = bytearray(journal.read_bytes())
    data[-20] ^= 0x04
    journal.write_bytes(bytes(data))


TAIL_DAMAGE: dict[str, Callable[[Path], None]] = {
    "the last 40 bytes cut": cut_40_bytes,
    "64 random bytes and a newline appended": append_garbage,
    "a bit flipped in the last record": flip_a_bit_of_the_last_record,
}


def stored_model(data: Path) -> Path:
    """The issue's model: 500 steps with a snapshot every 200, as a kill -9 leaves it."""
    registry = reopen(data, snapshot_every=200)
    registry.create("m", ShieldConfig())
    feed(registry, "m", 1, 500)
    return data / "models" / "m"


@pytest.mark.parametrize("case", sorted(TAIL_DAMAGE))
def test_steps_acknowledged_after_a_repair_survive_the_next_crash(
    tmp_path: Path, caplog: pytest.LogCaptureFixture, case: str
) -> None:
    model = stored_model(tmp_path)
    journal = model / "journal.log"
    intact = journal.read_bytes()
    TAIL_DAMAGE[case](journal)
    damaged = journal.read_bytes()
    with caplog.at_level(logging.ERROR):
        repaired = reopen(tmp_path, snapshot_every=200)
    assert "m" not in repaired.quarantined
    recovered = version(repaired)
    assert recovered >= 499  # at most the damaged last record is gone
    assert any(
        "'m'" in r.getMessage() and "repaired" in r.getMessage()
        for r in caplog.records
        if r.levelno >= logging.ERROR
    )
    # the cut bytes are kept beside the journal, which now ends at its last good record
    kept = list(model.glob("journal.log.damaged-*"))
    assert len(kept) == 1
    common = len(damaged) - len(kept[0].read_bytes())
    assert damaged[:common] + kept[0].read_bytes() == damaged
    assert intact.startswith(damaged[:common])
    feed(repaired, "m", 2, 60)  # acknowledged after the repair
    assert version(reopen(tmp_path, snapshot_every=200)) == recovered + 60


def test_a_bad_record_followed_by_good_ones_sets_the_model_aside(tmp_path: Path) -> None:
    model = stored_model(tmp_path)
    journal = model / "journal.log"
    lines = journal.read_bytes().split(b"\n")
    lines[1] = lines[1].replace(b'"o":[', b'"o":[9')  # its checksum fails, good lines follow
    journal.write_bytes(b"\n".join(lines))
    files = {p.name: p.read_bytes() for p in model.iterdir()}
    registry = reopen(tmp_path)
    assert "not at the end" in registry.quarantined["m"]
    with pytest.raises(ModelQuarantined):
        registry.step("m", Step([10.0, 20.0, 10.0], 0.1))
    assert {p.name: p.read_bytes() for p in model.iterdir()} == files


def test_a_journal_deleted_before_the_first_snapshot_is_damage_too(tmp_path: Path) -> None:
    registry = reopen(tmp_path)
    registry.create("m", ShieldConfig())
    feed(registry, "m", 1, 50)  # no snapshot taken yet by the steps themselves
    (tmp_path / "models" / "m" / "journal.log").unlink()
    assert "journal.log is missing" in reopen(tmp_path).quarantined["m"]


def test_a_model_created_without_steps_loads_and_gets_its_files(tmp_path: Path) -> None:
    """A store written before every model had a snapshot from birth: a model directory with
    config.json alone is a model that never learned; it is given a snapshot and a journal."""
    reopen(tmp_path).create("m", ShieldConfig())
    model = tmp_path / "models" / "m"
    for name in ("snapshot.npz", "journal.log"):
        (model / name).unlink()
    registry = reopen(tmp_path)
    assert version(registry) == 0
    assert (model / "snapshot.npz").exists() and (model / "journal.log").exists()


def test_a_journal_deleted_while_a_snapshot_was_written_is_damage_too(tmp_path: Path) -> None:
    """Killed while a snapshot was being written: journal.1.log holds the records it will
    cover, journal.log those after it; without journal.log the latter are unknown."""
    stored_model(tmp_path)
    model = tmp_path / "models" / "m"
    (model / "journal.1.log").write_bytes((model / "journal.log").read_bytes())
    (model / "journal.log").unlink()
    assert "journal.log is missing" in reopen(tmp_path).quarantined["m"]
