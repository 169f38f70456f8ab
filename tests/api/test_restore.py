"""PUT /models/{name} refuses every snapshot that could break a model (issue #45, findings
2-4): 422 ``invalid_snapshot`` naming the part at fault, nothing changed, memory bounded."""

from __future__ import annotations

import copy
import io
import json
import zipfile
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
import pytest
from fastapi.testclient import TestClient

from app.main import create_app
from app.settings import Settings
from tests.api.test_api import episode
from tests.utils import rewrite_npz_member

LIMIT = 4 * 2**20  # the test server's snapshot limit [bytes]


@pytest.fixture(scope="module")
def server() -> Iterator[tuple[TestClient, dict[str, Any], bytes]]:
    """A server with model 'a' after three episodes (two streams, one left open), its exact
    JSON snapshot and its .npz."""
    with TestClient(create_app(Settings(max_snapshot_bytes=LIMIT))) as c:
        c.post("/models", json={"name": "a"})
        for _ in range(3):
            episode(c, "/models/a/revise")
        c.post(
            "/models/a/revise",
            json={"observation": [12.0, 30.0, 11.0], "action": 0.3, "stream": "open"},
        )
        snapshot = c.get("/models/a", params={"tpm": "none"}).json()
        npz = c.get("/models/a", params={"format": "npz"}).content
        yield c, snapshot, npz


def tagged(snapshot: dict[str, Any], *path: str) -> dict[str, Any]:
    """The tagged array at ``path`` of the exact state."""
    part: Any = snapshot["exact"]
    for key in path:
        part = part[int(key)] if isinstance(part, list) else part[key]
    return part  # type: ignore[no-any-return]


def set_first(*path: str, value: Any) -> Callable[[dict[str, Any]], None]:
    def change(snapshot: dict[str, Any]) -> None:
        tagged(snapshot, *path)["data"][0] = value

    return change


def set_value(*path: str, value: Any) -> Callable[[dict[str, Any]], None]:
    def change(snapshot: dict[str, Any]) -> None:
        tagged(snapshot, *path[:-1])[path[-1]] = value

    return change


def removed_switch(snapshot: dict[str, Any]) -> None:
    """A configuration of the stored format's version 1 that used a switch removed since."""
    config = snapshot["exact"]["config"]
    del config["version"]
    config["observation"]["knee_shape"] = "double"  # the knee of version 1's last default
    config["reviser"]["noise_side"] = "away"


BROKEN = {
    "a switch removed since": (removed_switch, "config.reviser.noise_side"),
    "a belief's state out of range": (
        set_first("streams", "open", "index", value=999_999),
        "streams.open.index",
    ),
    "an applied bin out of range": (
        set_value("streams", "open", "applied_bin", value=999),
        "streams.open.applied_bin",
    ),
    "a negative cluster support": (
        set_first("clustering", "support", value=-3),
        "clustering.support",
    ),
    "NaN in the centres": (
        set_first("clustering", "centres", value=float("nan")),
        "clustering.centres",
    ),
    "infinity in a matrix": (
        set_first("transitions", "actions", "12", "vals", value=float("inf")),
        "transitions.actions.12.vals",
    ),
    "more states than max_states": (
        set_value("config", "limits", "max_states", value=1),
        "clustering.centres",
    ),
    "a negative model version": (
        set_value("counters", "model_version", value=-5),
        "counters.model_version",
    ),
    "an object dtype": (
        set_value("clustering", "beta", "__array__", value="|O"),
        "clustering.beta",
    ),
    "a dtype numpy cannot read": (
        set_value("clustering", "beta", "__array__", value="zz9"),
        "clustering.beta",
    ),
    "a dtype of 2 GB items": (
        set_value("clustering", "beta", "__array__", value="V2000000000"),
        "clustering.beta",
    ),
    "a shape beyond its data": (
        set_value("clustering", "centres", "shape", value=[10**9]),
        "clustering.centres",
    ),
    "a belief that is not a distribution": (
        set_first("streams", "open", "prob", value=-0.5),
        "streams.open.prob",
    ),
    "a risk covariance beyond its prior": (
        set_first("local_risk", "cov", value=1e6),
        "local_risk.cov",
    ),
}


@pytest.mark.parametrize("case", sorted(BROKEN))
def test_a_snapshot_that_would_break_the_model_is_refused(
    server: tuple[TestClient, dict[str, Any], bytes], case: str
) -> None:
    client, snapshot, _ = server
    change, field = BROKEN[case]
    broken = copy.deepcopy(snapshot)
    change(broken)
    body = json.dumps(broken)  # NaN and Infinity as Python writes them
    before = client.get("/models").json()
    r = client.put("/models/a", content=body, headers={"content-type": "application/json"})
    assert r.status_code == 422, r.text
    error = r.json()["error"]
    assert error["code"] == "invalid_snapshot" and error["field"] == field, error
    assert client.get("/models").json() == before  # nothing changed, no model added
    step = {"observation": [12.0, 30.0, 11.0], "action": 0.3, "stream": "open"}
    assert client.post("/models/a/revise", json={**step, "learn": False}).status_code == 200


def npz_cases(npz: bytes) -> dict[str, bytes]:
    """Damaged copies of an archive; the bit flip lands in the compressed data of its largest
    member (a flip in a local header's extra field would be harmless)."""
    with zipfile.ZipFile(io.BytesIO(npz)) as archive:
        largest = max(archive.infolist(), key=lambda info: info.compress_size)
    data_start = (
        largest.header_offset
        + 30
        + len(largest.filename.encode())
        + int.from_bytes(npz[largest.header_offset + 28 : largest.header_offset + 30], "little")
    )
    flipped = bytearray(npz)
    flipped[data_start + largest.compress_size // 2] ^= 0xFF
    return {
        "empty": b"",
        "truncated": npz[: len(npz) // 2],
        "bit-flipped": bytes(flipped),
        "not a zip": b"PK\x03\x04" + b"\x00" * 64,
    }


@pytest.mark.parametrize("case", ["empty", "truncated", "bit-flipped", "not a zip"])
def test_a_damaged_archive_is_refused(
    server: tuple[TestClient, dict[str, Any], bytes], case: str
) -> None:
    client, _, npz = server
    r = client.put(
        "/models/damaged",
        content=npz_cases(npz)[case],
        headers={"content-type": "application/x-npz"},
    )
    assert r.status_code == 422 and r.json()["error"]["code"] == "invalid_snapshot", r.text
    assert client.get("/models/damaged").status_code == 404


def test_deeply_nested_json_is_refused(server: tuple[TestClient, dict[str, Any], bytes]) -> None:
    client, _, _ = server
    r = client.put(
        "/models/deep", content=b"[" * 100_000, headers={"content-type": "application/json"}
    )
    assert r.status_code == 422 and r.json()["error"]["code"] == "invalid_snapshot"


def bomb(size: int) -> bytes:
    """A .npz whose member inflates to ``size`` bytes of zeros from a few kilobytes."""
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as archive:
        array = io.BytesIO()
        np.lib.format.write_array_header_1_0(
            array, {"descr": "<f8", "fortran_order": False, "shape": (size // 8,)}
        )
        with archive.open("big.npy", "w", force_zip64=True) as member:
            member.write(array.getvalue())
            chunk = bytes(2**20)
            for _ in range(size // len(chunk)):
                member.write(chunk)
    return buffer.getvalue()


def test_an_archive_that_inflates_beyond_the_limit_is_refused_unread(
    server: tuple[TestClient, dict[str, Any], bytes],
) -> None:
    client, _, _ = server
    blob = bomb(64 * 2**20)
    assert len(blob) < LIMIT // 8
    r = client.put("/models/bomb", content=blob, headers={"content-type": "application/x-npz"})
    assert r.status_code == 422 and r.json()["error"]["field"] == "body", r.text


def test_a_header_that_claims_more_than_its_data_is_refused(
    server: tuple[TestClient, dict[str, Any], bytes],
) -> None:
    client, _, npz = server
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(
        header, {"descr": "<f8", "fortran_order": False, "shape": (10**8,)}
    )
    liar = rewrite_npz_member(
        npz, "/clustering/beta.npy", lambda _: header.getvalue() + b"\x00" * 24
    )
    r = client.put("/models/liar", content=liar, headers={"content-type": "application/x-npz"})
    assert r.status_code == 422, r.text
    assert r.json()["error"]["field"] == "/clustering/beta", r.text


def test_the_untouched_snapshots_still_restore(
    server: tuple[TestClient, dict[str, Any], bytes],
) -> None:
    client, snapshot, npz = server
    assert client.put("/models/copy-json", json=snapshot).status_code == 200
    assert (
        client.put(
            "/models/copy-npz", content=npz, headers={"content-type": "application/x-npz"}
        ).status_code
        == 200
    )


def test_a_local_risk_model_round_trips_over_http_and_refuses_its_damage() -> None:
    with TestClient(create_app(Settings(max_snapshot_bytes=LIMIT))) as c:
        config = {"risk": {"horizon": 4}}
        assert c.post("/models", json={"name": "l", "config": config}).status_code == 201
        for _ in range(3):
            episode(c, "/models/l/revise")
        step = {"observation": [12.0, 3.0, 11.0], "action": 1.5, "stream": "open"}
        for _ in range(2):  # the second step queues the first for its label
            c.post("/models/l/revise", json=step)
        snapshot = c.get("/models/l", params={"tpm": "none"}).json()
        assert snapshot["exact"]["local_risk"]["streams"] == ["open"]
        npz = c.get("/models/l", params={"format": "npz"}).content
        assert c.put("/models/l-json", json=snapshot).status_code == 200
        assert (
            c.put(
                "/models/l-npz", content=npz, headers={"content-type": "application/x-npz"}
            ).status_code
            == 200
        )
        answers = [
            c.post(f"/models/{name}/revise", json=step).json() for name in ("l", "l-json", "l-npz")
        ]
        assert answers[0]["risk"] == answers[1]["risk"] == answers[2]["risk"]
        assert answers[0]["action"] == answers[1]["action"] == answers[2]["action"]
        broken = copy.deepcopy(snapshot)
        tagged(broken, "local_risk", "theta")["data"][0] = float("nan")
        r = c.put(
            "/models/l", content=json.dumps(broken), headers={"content-type": "application/json"}
        )
        assert r.status_code == 422 and r.json()["error"]["field"] == "local_risk.theta"
