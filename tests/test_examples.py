"""The examples run as written (with fewer steps) and print what they say they print."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


@pytest.mark.parametrize(("script", "args", "pattern"), [
    ("pendulum_overspeed.py", ["--episodes", "6", "--warmup", "2"],
     r"overspeed steps per 1000: alone [\d.]+, shielded [\d.]+"),
    ("td3_car_following.py", ["--steps", "300"],
     r"alone: [\d.]+ failures per 1000 steps.*\n\s*shielded: [\d.]+ failures per 1000 steps"),
    ("vectorised.py", ["--steps", "200"], r"one model, \d+ open streams, \d+ steps"),
    ("gymnasium_vector.py", ["--steps", "300", "--mode", "async"],
     r"8 copies, one model: 2400 steps, \d+ states"),
    ("remote_service.py", ["--steps", "200"],
     r"model td3-car at http://127\.0\.0\.1:\d+: .*'streams': 0"),
])
def test_an_example_runs(script: str, args: list[str], pattern: str) -> None:
    out = subprocess.run([sys.executable, str(EXAMPLES / script), *args], capture_output=True,
                         text=True, timeout=300, cwd=EXAMPLES.parent)
    assert out.returncode == 0, out.stderr[-2000:]
    assert re.search(pattern, out.stdout), out.stdout
