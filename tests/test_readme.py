"""The README's Python snippets run as written: the in-process core, the Python client against a
live service (the README's address swapped for the test server's), and the Gymnasium and SB3
wrapper."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

from tests.conftest import start_server

pytestmark = pytest.mark.slow  # a real server, TD3 training

README = Path(__file__).resolve().parent.parent / "README.md"


def snippet(section: str) -> str:
    """The first Python block under the README heading ``section``."""
    text = README.read_text()
    body = text[text.index(f"\n## {section}\n") :]
    found = re.search(r"```python\n(.*?)```", body, re.DOTALL)
    assert found is not None, section
    return found.group(1)


def run(code: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=300, cwd=cwd
    )


def test_the_core_snippet_runs(tmp_path: Path) -> None:
    done = run(snippet("Use the core in-process"), tmp_path)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout == "0.8 cold_start\n"  # the first step of a fresh model keeps it


def test_the_python_client_snippet_runs_against_a_live_service(tmp_path: Path) -> None:
    code = snippet("Run the shield as a service")
    assert code.count("http://127.0.0.1:8000") == 2 and 'token="change-me"' in code
    server = start_server(tmp_path / "data", "--token", "change-me")
    try:
        done = run(code.replace("http://127.0.0.1:8000", server.url), tmp_path)
    finally:
        server.stop()
    assert done.returncode == 0, done.stderr[-2000:]
    assert '"POST /revise HTTP/1.1" 200' in server.log.read_text()


def test_the_gymnasium_snippet_runs(tmp_path: Path) -> None:
    done = run(snippet("Use it from Gymnasium and Stable-Baselines3"), tmp_path)
    assert done.returncode == 0, done.stderr[-2000:]
