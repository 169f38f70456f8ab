"""Checkpoints of a lockstep group: where each run of the group stands in its episode (the
simulator, the episode so far, its shield model) and everything its learner holds, so that a
long experiment, stopped on purpose or cut off, goes on from there instead of replaying every
episode from the start.

A run continued from a checkpoint makes exactly the steps it would have made uninterrupted;
episodes recorded after the checkpoint was written are replayed and checked like any replay.
A checkpoint is written whole or not at all, and removed when its group is done.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import torch

from client.experiment.records import RecordError

DIRECTORY = "checkpoints"
FORMAT = 2  # 2: the learner's weights and Adam moments as flat buffers (DDPGEnsemble.state)


def path_for(out: Path, arm: str, group: Sequence[int]) -> Path:
    return out / DIRECTORY / f"{arm.replace('+', '_')}__runs{group[0]:02d}-{group[-1]:02d}.pt"


def pending(out: Path) -> list[Path]:
    """The checkpoints of groups not yet done."""
    return sorted((out / DIRECTORY).glob("*.pt"))


def save(path: Path, identity: dict[str, Any], state: dict[str, Any]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_suffix(".partial")
    with open(partial, "wb") as f:
        torch.save({"format": FORMAT, "identity": identity, "state": state}, f)
        f.flush()
        os.fsync(f.fileno())
    partial.replace(path)


def load(path: Path, identity: dict[str, Any]) -> dict[str, Any] | None:
    """The state saved at ``path``, or None when there is none; a checkpoint of another
    experiment or group is refused, not silently replaced."""
    if not path.exists():
        return None
    # our own file, holding numpy generator states and Python objects besides tensors
    saved = torch.load(path, map_location="cpu", weights_only=False)
    if saved.get("format") != FORMAT:
        raise RecordError(
            f"{path}: a checkpoint of format {saved.get('format')}, written by "
            f"another version of the client (this one reads {FORMAT}); remove it "
            f"to start the group again"
        )
    if saved.get("identity") != identity:
        raise RecordError(
            f"{path}: a checkpoint of another experiment or group; remove it to "
            f"start the group again"
        )
    state: dict[str, Any] = saved["state"]
    return state


def remove(path: Path) -> None:
    path.unlink(missing_ok=True)
