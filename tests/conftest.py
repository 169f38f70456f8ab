"""Shared fixtures: an in-process app client and a real server on 127.0.0.1."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import httpx
import pytest
from fastapi.testclient import TestClient
from hypothesis import settings

from app.main import create_app
from app.settings import Settings

settings.register_profile("project", max_examples=40, derandomize=True, deadline=None)
settings.load_profile("project")


@pytest.fixture(autouse=True, scope="session")
def sb3_logs_in_the_test_tmp(tmp_path_factory: pytest.TempPathFactory) -> None:
    """SB3 gives every model a logger folder under ``SB3_LOGDIR`` (the system's temp folder
    when unset, where they would pile up); the examples' subprocesses inherit it."""
    os.environ["SB3_LOGDIR"] = str(tmp_path_factory.mktemp("sb3"))


@pytest.fixture
def client() -> Iterator[TestClient]:
    """The app in memory, lifespan included."""
    with TestClient(create_app(Settings())) as c:
        yield c


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


@dataclass
class Server:
    """A shield service in its own process."""

    url: str
    data_dir: Path
    process: subprocess.Popen[bytes]
    log: Path

    def kill(self) -> None:
        self.process.send_signal(signal.SIGKILL)
        self.process.wait(10)

    def stop(self) -> None:
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)
            try:
                self.process.wait(10)
            except subprocess.TimeoutExpired:
                self.kill()


def start_server(
    data_dir: Path, *args: str, env: dict[str, str] | None = None, wrapper: Sequence[str] = ()
) -> Server:
    """``python -m app serve`` on a free port (run by ``wrapper``, as ``prlimit --as=...``,
    if given); returns once /readyz answers 200."""
    port = free_port()
    log = data_dir.parent / f"server-{port}.log"
    command = [
        *wrapper,
        sys.executable,
        "-m",
        "app",
        "serve",
        "--host",
        "127.0.0.1",
        "--port",
        str(port),
        "--data-dir",
        str(data_dir),
        *args,
    ]
    process = subprocess.Popen(
        command, stdout=open(log, "wb"), stderr=subprocess.STDOUT, env={**os.environ, **(env or {})}
    )
    url = f"http://127.0.0.1:{port}"
    deadline = time.monotonic() + 300  # a cold kernel cache compiles first: a minute or more
    while time.monotonic() < deadline:
        if process.poll() is not None:
            raise RuntimeError(f"server exited: {log.read_text()}")
        try:
            if httpx.get(url + "/readyz", timeout=1).status_code == 200:
                return Server(url, data_dir, process, log)
        except httpx.TransportError:
            time.sleep(0.1)
    process.kill()
    raise RuntimeError(f"server did not start: {log.read_text()}")


@pytest.fixture
def live_server(tmp_path: Path) -> Iterator[Server]:
    """A real server with a data directory and fsync=always; stopped after the test."""
    server = start_server(tmp_path / "data", "--fsync", "always")
    yield server
    server.stop()
