"""Small factories and comparisons shared by the tests."""

from __future__ import annotations

import io
import zipfile
from collections.abc import Callable
from typing import Any

import numpy as np

from app.core import Shield, ShieldConfig
from app.core.config import ActionSpec, Criterion, ObservationSpec, ReviserConfig


def assert_same(a: Any, b: Any, path: str = "") -> None:
    """Deep equality of snapshot-like data: dicts, lists, scalars and numpy arrays (bitwise)."""
    if isinstance(a, dict):
        assert isinstance(b, dict) and a.keys() == b.keys(), path
        for key in a:
            assert_same(a[key], b[key], f"{path}.{key}")
    elif isinstance(a, list | tuple):
        assert isinstance(b, list | tuple) and len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            assert_same(x, y, f"{path}[{i}]")
    elif isinstance(a, np.ndarray):
        np.testing.assert_array_equal(a, np.asarray(b), err_msg=path)
        assert a.dtype == np.asarray(b).dtype, path
    else:
        assert a == b, f"{path}: {a!r} != {b!r}"


def random_stream(seed: int, n: int, dim: int = 3) -> list[tuple[list[float], float, bool]]:
    """A reproducible stream of (observation, action, done) in the paper's units."""
    rng = np.random.default_rng(seed)
    high = np.array([32.0, 200.0, 32.0])[:dim]
    steps = []
    z = rng.uniform(0, high)
    for t in range(n):
        done = (t + 1) % 25 == 0
        if t % 25 == 0:  # each episode starts somewhere new
            z = rng.uniform(0, high)
        z = np.clip(z + rng.normal(0, 0.05, dim) * high, 0, high)
        steps.append(([float(v) for v in z], float(rng.uniform(-2, 2)), done))
    return steps


CLIFF_OBSERVATION = ObservationSpec(names=("x",), low=(0.0,), high=(1.0,), knee=())
# the paper's criteria, without the car-following bounds (there is no headway here)
CLIFF_CRITERIA = (Criterion("collision", "decrease"), Criterion("large_distance", "increase"))


def cliff_config(**reviser: Any) -> ShieldConfig:
    """A one-dimensional world for the behavioural tests (see :func:`run_cliff`), with the
    paper's reviser unless ``method`` says otherwise."""
    options: dict[str, Any] = {
        "method": "paper",
        "activate_after_episodes": 10,
        "noise_k": 1.0,
        "noise": "std",
    }
    options.update(reviser)
    return ShieldConfig(
        observation=CLIFF_OBSERVATION,
        action=ActionSpec(),
        criteria=CLIFF_CRITERIA,
        reviser=ReviserConfig(**options),
    )


def run_cliff(
    shield: Shield | None, episodes: int, seed: int, steps: int = 10
) -> tuple[list[bool], list[tuple[float, float]]]:
    """Drive a random controller in a world where every action above 1.0 m/s² falls off a cliff.

    Safe actions keep x around 0.5; an action in [1.0, 2.0] moves x to 0.95, a collision that
    ends the episode. Returns whether each episode failed and every (proposed, applied) pair.
    """
    rng = np.random.default_rng(seed)
    failed, pairs = [], []
    for _ in range(episodes):
        x, crashed = 0.5, False
        for _ in range(steps):
            proposed = float(rng.uniform(-2.0, 2.0))
            applied = proposed
            if shield is not None:
                decision = shield.step([x], proposed)
                assert decision.action is not None
                applied = decision.action
            pairs.append((proposed, applied))
            if applied >= 1.0:
                x, crashed = 0.95, True
                break
            x = 0.5 + float(rng.uniform(-0.05, 0.05))
        if shield is not None:
            shield.step([x], None, event="collision" if crashed else None, done=True)
        failed.append(crashed)
    return failed, pairs


def rewrite_npz_member(npz: bytes, member: str, change: Callable[[bytes], bytes]) -> bytes:
    """An ``.npz`` snapshot with the bytes of one member replaced by ``change`` of them."""
    buffer = io.BytesIO()
    with (
        zipfile.ZipFile(io.BytesIO(npz)) as source,
        zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as target,
    ):
        for info in source.infolist():
            data = source.read(info)
            target.writestr(info.filename, change(data) if info.filename == member else data)
    return buffer.getvalue()
