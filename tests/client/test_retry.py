"""The clients' ``retry``: a step is sent again, with the same idempotency key, until a server
answers it, and the server applies it once (docs/api.md, "Sending a step again")."""

from __future__ import annotations

import asyncio
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import httpx
import pytest

from client.shield import (
    AsyncShieldClient,
    Retry,
    ShieldAPIError,
    ShieldClient,
    ShieldSession,
    ShieldUnavailable,
)
from client.shield.remote import worth_retrying
from client.shield.retry import call_with_retry
from tests.conftest import free_port

PATIENT = Retry(attempts=400, backoff=0.1, max_backoff=0.3)  # a server starting under load
STEP: dict[str, Any] = {"observation": [10.0, 50.0, 12.0], "action": 0.5}


def serve(data: Path, port: int, delay: float = 0.0) -> subprocess.Popen[bytes]:
    """``python -m app serve`` on ``port``, started after ``delay`` seconds."""
    time.sleep(delay)
    return subprocess.Popen(
        [
            sys.executable,
            "-m",
            "app",
            "serve",
            "--host",
            "127.0.0.1",
            "--port",
            str(port),
            "--data-dir",
            str(data),
            "--fsync",
            "always",
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        env=dict(os.environ),
    )


def later(data: Path, port: int, started: list[subprocess.Popen[bytes]]) -> threading.Thread:
    thread = threading.Thread(target=lambda: started.append(serve(data, port, 0.5)))
    thread.start()
    return thread


def version(url: str) -> int:
    result: int = httpx.get(url + "/models/default", params={"tpm": "none"}).json()["model_version"]
    return result


def test_each_client_sends_again_until_answered_and_the_step_is_applied_once(
    tmp_path: Path,
) -> None:
    port, data = free_port(), tmp_path / "data"
    url = f"http://127.0.0.1:{port}"
    started: list[subprocess.Popen[bytes]] = []
    try:
        waiting = later(data, port, started)  # nothing listens yet
        with ShieldClient(url, model="default", retry=PATIENT) as shield:
            first = shield.revise(**STEP, idempotency_key="http")
            waiting.join()
            assert shield.revise(**STEP, idempotency_key="http") == first
            batch = shield.revise_batch([{**STEP, "action": 0.1}, {**STEP, "action": 0.2}])
        assert [d.model_version for d in batch] == [2, 3]

        async def revise_async() -> None:
            async with AsyncShieldClient(url, retry=PATIENT) as shield:
                decision = await shield.revise(**STEP, idempotency_key="async")
                assert await shield.revise(**STEP, idempotency_key="async") == decision

        asyncio.run(revise_async())
        assert version(url) == 4
        with ShieldSession(url, retry=PATIENT) as session:
            session.revise(**STEP, idempotency_key="ws-1")
            started.pop().send_signal(signal.SIGKILL)  # the session is lost ...
            waiting = later(data, port, started)  # ... and a server comes back
            decision = session.revise(**STEP, idempotency_key="ws-2")
            waiting.join()
            assert session.revise(**STEP, idempotency_key="ws-2") == decision
        assert decision.model_version == version(url) == 6
    finally:
        for process in started:
            process.kill()
            process.wait(10)


def test_a_refusal_is_not_sent_again() -> None:
    calls: list[int] = []

    def refused() -> None:
        calls.append(1)
        raise ShieldAPIError(503, "model_quarantined", "set aside", "name")

    with pytest.raises(ShieldAPIError):
        call_with_retry(refused, Retry(attempts=3, backoff=0), worth_retrying)
    assert len(calls) == 1

    def unanswered() -> None:
        calls.append(1)
        raise ShieldUnavailable("no answer")

    with pytest.raises(ShieldUnavailable):
        call_with_retry(unanswered, Retry(attempts=3, backoff=0), worth_retrying)
    assert len(calls) == 4  # one refusal, then three sends that got no answer
