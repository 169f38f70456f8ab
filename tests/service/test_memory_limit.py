"""Under a 1 GB address space (``prlimit --as``), hostile requests get answers, not a server
error or a crash (issue 69): configurations that would size huge tables, uploads that inflate,
many at once, and a flood of streams. The idle server with its compiled core takes about
640 MB of address space (numba and LLVM included), so 1 GB leaves it under 400 MB to serve.
"""

from __future__ import annotations

import io
import json
import shutil
import zipfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import httpx
import pytest

from tests.api.test_hostile import with_member
from tests.conftest import start_server

pytestmark = pytest.mark.slow  # starts a real server under prlimit

ADDRESS_SPACE = 2**30  # [bytes]
SNAPSHOT_LIMIT = 32 * 2**20  # [bytes] the server's max_snapshot_bytes


@pytest.mark.skipif(shutil.which("prlimit") is None, reason="needs util-linux prlimit")
def test_hostile_requests_under_a_1_gb_address_space(tmp_path: Path) -> None:
    server = start_server(
        tmp_path / "data",
        "--max-snapshot-bytes",
        str(SNAPSHOT_LIMIT),
        "--max-models",
        "4",
        "--max-model-bytes",
        str(128 * 2**20),
        "--max-concurrent-restores",
        "2",
        wrapper=("prlimit", f"--as={ADDRESS_SPACE}"),
    )
    answers: list[int] = []
    try:
        with httpx.Client(base_url=server.url, timeout=120) as client:

            def send(method: str, path: str, **kwargs: Any) -> httpx.Response:
                response = client.request(method, path, **kwargs)
                answers.append(response.status_code)
                return response

            def create(config: dict[str, Any]) -> int:
                body = json.dumps({"name": "huge", "config": config})  # Infinity as Python writes
                return send(
                    "POST", "/models", content=body, headers={"content-type": "application/json"}
                ).status_code

            for config in (
                {"action": {"low": 0, "high": 1e9, "step": 1}},
                {"action": {"low": 0, "high": 1e7, "step": 1}},
                {"limits": {"max_states": 1_000_000, "max_streams": 1_000_000}},
                {"limits": {"tpm_backend": "dense", "max_states": 100_000}},
                {"limits": {"belief_top_k": 10**9}},
                {"risk": {"horizon": 256}, "limits": {"max_streams": 1_000_000}},
                {"clustering": {"min_variance": float("inf")}},
            ):
                assert create(config) == 422, config

            for i in range(40):  # a model's steps, then a snapshot of it
                send(
                    "POST",
                    "/revise",
                    json={
                        "observation": [10.0 + i % 7, 30.0 - i % 11, 11.0],
                        "action": 0.2,
                        "stream": f"car-{i % 3}",
                    },
                )
            npz = send("GET", "/model", params={"format": "npz"}).content
            padded = with_member(npz, "padding.npy", 30 * 2**20)  # named by nothing
            oversized = b'{"exact": {"pad": "' + b"x" * (SNAPSHOT_LIMIT - 64) + b'"}}'
            buffer = io.BytesIO()
            with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as archive:
                archive.writestr("meta.npy", npz[:100])  # a damaged archive
            uploads = [
                (padded, "application/x-npz"),
                (oversized, "application/json"),
                (buffer.getvalue(), "application/x-npz"),
                (npz, "application/x-npz"),
            ] * 3

            def upload(i: int) -> int:
                blob, kind = uploads[i]
                return send(
                    "PUT", f"/models/up-{i % 3}", content=blob, headers={"content-type": kind}
                ).status_code

            with ThreadPoolExecutor(6) as pool:  # many at once
                statuses = list(pool.map(upload, range(len(uploads))))
            assert set(statuses) <= {200, 413, 422}, statuses
            assert 200 in statuses and 422 in statuses and 413 in statuses

            steps = [
                {"observation": [10.0, 25.0, 10.0], "action": 0.1, "stream": f"s{i}"}
                for i in range(2000)
            ]  # a flood of streams, within the model's bound
            for start in range(0, len(steps), 500):
                send("POST", "/revise/batch", json={"steps": steps[start : start + 500]})
            assert send("GET", "/readyz").status_code == 200
            assert send("GET", "/model", params={"tpm": "dense"}).status_code == 200
        assert server.process.poll() is None, server.log.read_text()[-2000:]
        assert all(status < 500 for status in answers), answers
        assert "MemoryError" not in server.log.read_text()
    finally:
        server.stop()
