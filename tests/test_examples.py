"""The examples run as written (with fewer steps) and print what they say they print; the
Gymnasium guide's snippets run as one session."""

from __future__ import annotations

import importlib.util
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = ROOT / "examples"
GUIDE = ROOT / "docs" / "gymnasium.md"
LOADING = "loading the shield's compiled core"


def run(script: str, *args: str) -> subprocess.CompletedProcess[str]:
    """``script`` run as its docstring says, with ``args``; it must succeed."""
    out = subprocess.run(
        [sys.executable, str(EXAMPLES / script), *args],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=ROOT,
    )
    assert out.returncode == 0, out.stderr[-2000:]
    return out


@pytest.mark.parametrize(
    ("script", "args", "pattern"),
    [
        (
            "pendulum_overspeed.py",
            ["--episodes", "6", "--warmup", "2"],
            r"overspeed steps per 1000: alone [\d.]+, shielded [\d.]+",
        ),
        ("vectorised.py", ["--steps", "200"], r"one model, \d+ open streams, \d+ steps"),
        (
            "gymnasium_vector.py",
            ["--steps", "300", "--mode", "async"],
            r"8 copies, one model: 2400 steps, \d+ states",
        ),
        (
            "remote_service.py",
            ["--steps", "200"],
            r"answering after \d+ s\n(.*\n)*"
            r"model td3-car at http://127\.0\.0\.1:\d+: .*'streams': 0",
        ),
    ],
)
def test_an_example_runs(script: str, args: list[str], pattern: str) -> None:
    out = run(script, *args)
    assert re.search(pattern, out.stdout), out.stdout
    assert LOADING in out.stdout or "starting the shield service" in out.stdout


def test_td3_warns_when_the_run_is_too_short_for_the_shield_to_act() -> None:
    never = run("td3_car_following.py", "--steps", "300", "--warmup", "300")
    assert "the shield acts after step 300" in never.stdout
    assert "it never acts, and both arms meet the same failures" in never.stderr
    assert re.search(
        r"alone: [\d.]+ failures per 1000 steps.*\n\s*shielded: [\d.]+ failures "
        r"per 1000 steps .*, 0 actions revised",
        never.stdout,
    ), never.stdout
    scaled = run("td3_car_following.py", "--steps", "300")  # the warm-up is a quarter: 75
    assert "the shield acts after step 75" in scaled.stdout
    assert "never acts" not in scaled.stderr
    revised = int(re.findall(r"(\d+) actions revised", scaled.stdout)[-1])
    assert (revised == 0) == ("the shield revised no action" in scaled.stderr), scaled.stderr


def guide_blocks() -> list[str]:
    """The guide's Python snippets, in order."""
    return re.findall(r"```python\n(.*?)```", GUIDE.read_text(), re.S)


def test_the_gymnasium_guide_runs(tmp_path: Path) -> None:
    blocks = guide_blocks()
    assert len(blocks) >= 8
    # the highway-env snippet needs highway-env, which the project does not install
    runnable = [
        b
        for b in blocks
        if "import highway_env" not in b or importlib.util.find_spec("highway_env") is not None
    ]
    assert len(blocks) - len(runnable) <= 1
    script = tmp_path / "guide.py"
    script.write_text("\n".join(runnable))
    out = subprocess.run(
        [sys.executable, str(script)], capture_output=True, text=True, timeout=300, cwd=ROOT
    )
    assert out.returncode == 0, out.stderr[-3000:]
    assert (
        "observation_space -> observation_space: the observation space Box(-inf, inf" in out.stdout
    )
    assert "NoFailureReported 3 episodes terminated" in out.stdout
    assert re.search(r"\d+/300 steps, \d+ episodes", out.stdout), out.stdout
