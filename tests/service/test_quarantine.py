"""A model whose files are damaged is set aside at start-up; every other model serves, nothing
is replaced silently, and every loss is logged (issue #45, findings 6 and 7; issue #69,
finding 7)."""

from __future__ import annotations

import json
import logging
import zlib
from collections.abc import Callable
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from app.core import ShieldConfig
from app.main import create_app
from app.service.registry import ModelQuarantined, ModelRegistry, Step
from app.settings import Settings
from tests.utils import random_stream


def feed(registry: ModelRegistry, name: str, seed: int, n: int) -> None:
    for z, a, done in random_stream(seed, n):
        registry.step(name, Step(z, None if done else a, done=done))


def stored(data: Path, snapshot_every: int) -> None:
    """Models 'good' and 'bad' (and 'default'), as a crash would leave them: 'bad' has a
    snapshot and a journal after it when ``snapshot_every`` is small, a journal alone when
    it is large."""
    registry = ModelRegistry(data, fsync="always", snapshot_every=snapshot_every)
    registry.open()
    for name in ("good", "bad"):
        registry.create(name, ShieldConfig())
        feed(registry, name, 1, 130)


def journal_line(record: dict[str, object]) -> bytes:
    payload = json.dumps(record, separators=(",", ":")).encode()
    return f"{zlib.crc32(payload):08x} ".encode() + payload + b"\n"


def truncate_snapshot(model: Path) -> None:
    blob = (model / "snapshot.npz").read_bytes()
    (model / "snapshot.npz").write_bytes(blob[: len(blob) // 2])


def flip_snapshot(model: Path) -> None:
    blob = bytearray((model / "snapshot.npz").read_bytes())
    for i in range(100, len(blob), 97):
        blob[i] ^= 0x5A
    (model / "snapshot.npz").write_bytes(bytes(blob))


def bad_journal_record(model: Path) -> None:
    lines = (model / "journal.log").read_bytes().splitlines()
    version = json.loads(lines[-1].split(b" ", 1)[1])["v"]
    record = {
        "v": version + 1,
        "steps": [{"o": [1.0], "a": 0.1, "s": "0", "e": None, "d": False, "p": None, "h": False}],
    }
    with open(model / "journal.log", "ab") as f:
        f.write(journal_line(record))  # a valid checksum, an observation of the wrong size


def bad_config(model: Path) -> None:
    (model / "config.json").write_text('{"reviser": {"method": "oracle"}}')


def missing_config(model: Path) -> None:
    (model / "config.json").unlink()


def garbage_config(model: Path) -> None:
    (model / "config.json").write_bytes(b"\x00garbage{")


def missing_journal(model: Path) -> None:
    (model / "journal.log").unlink()  # the steps after the snapshot are unknown


def missing_snapshot(model: Path) -> None:
    (model / "snapshot.npz").unlink()  # the journal goes on from the snapshot's version


DAMAGE: dict[str, tuple[Callable[[Path], None], int]] = {
    "a truncated snapshot": (truncate_snapshot, 50),
    "a corrupted snapshot": (flip_snapshot, 50),
    "a journal record with a valid checksum that no step can be": (bad_journal_record, 10**6),
    "a bad config.json": (bad_config, 10**6),
    "config.json missing beside a journal": (missing_config, 10**6),
    "garbage config.json beside a good snapshot": (garbage_config, 50),
    "journal.log missing beside its snapshot": (missing_journal, 50),
    "the snapshot missing before its journal": (missing_snapshot, 50),
}


@pytest.mark.parametrize("case", sorted(DAMAGE))
def test_a_damaged_model_is_set_aside_and_the_others_serve(
    tmp_path: Path, caplog: pytest.LogCaptureFixture, case: str
) -> None:
    damage, snapshot_every = DAMAGE[case]
    stored(tmp_path, snapshot_every)
    model = tmp_path / "models" / "bad"
    damage(model)
    files = {p.name: p.read_bytes() for p in model.iterdir()}
    with caplog.at_level(logging.ERROR):
        registry = ModelRegistry(tmp_path, fsync="always")
        registry.open()
    assert "bad" in registry.quarantined
    assert any("'bad' is quarantined" in r.getMessage() for r in caplog.records)
    with pytest.raises(ModelQuarantined):
        registry.step("bad", Step([10.0, 20.0, 10.0], 0.1))
    with pytest.raises(ModelQuarantined):
        registry.create("bad", ShieldConfig())  # no fresh model over the damaged files
    feed(registry, "good", 2, 20)  # the others serve
    registry.step("default", Step([10.0, 20.0, 10.0], 0.1))
    registry.close()
    assert {p.name: p.read_bytes() for p in model.iterdir()} == files  # kept as they were


def test_a_damaged_default_model_is_not_replaced_by_a_fresh_one(tmp_path: Path) -> None:
    registry = ModelRegistry(tmp_path, fsync="always")
    registry.open()
    feed(registry, "default", 3, 40)
    (tmp_path / "models" / "default" / "config.json").write_text("{not json")
    again = ModelRegistry(tmp_path, fsync="always")
    again.open()
    assert "default" in again.quarantined and "default" not in again.names()
    assert (tmp_path / "models" / "default" / "config.json").read_text() == "{not json"


def test_the_service_names_a_quarantined_model_and_answers_503(tmp_path: Path) -> None:
    stored(tmp_path, 50)
    truncate_snapshot(tmp_path / "models" / "bad")
    with TestClient(create_app(Settings(data_dir=tmp_path))) as client:
        ready = client.get("/readyz")
        assert ready.status_code == 200 and "bad" in ready.json()["quarantined"]
        r = client.post("/models/bad/revise", json={"observation": [1.0, 2.0, 3.0], "action": 0.1})
        assert r.status_code == 503
        assert r.json()["error"]["code"] == "model_quarantined"
        assert (
            client.post(
                "/models/good/revise", json={"observation": [1.0, 2.0, 3.0], "action": 0.1}
            ).status_code
            == 200
        )
