"""What a step hands the model, what each stream remembers between its steps, and the
model's totals."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from app.core.belief import Belief
from app.core.trial import NONE

FloatArray = npt.NDArray[np.float64]


@dataclass(slots=True)
class StepInput:
    """A validated step: what :meth:`Shield.apply` consumes (made on every step: a plain
    slotted record, not a frozen one, whose constructor costs several times as much)."""

    observation: FloatArray
    action: float | None
    action_bin: int  # the proposal's bin (0 without a proposal)
    stream: str
    event: int | None
    done: bool
    applied_bin: int  # the bin of the action the controller applied, if it says (-1: not)
    learn: bool
    shadow: bool


@dataclass
class StreamState:
    """What a stream remembers between its steps: tau and the action behind the transition,
    and its slot in the tables kept per stream (the local risk model's unlabelled steps)."""

    slot: int
    belief: Belief | None = None
    applied_bin: int = 0
    proposed_bin: int = 0
    step: int = 0
    recognised: int = -1  # the belief's most likely state, -1 without a belief
    z: FloatArray | None = None  # the normalised observation behind ``belief``
    arm: int = NONE  # the episode's arm in the shield's trial of itself (:mod:`app.core.trial`)
    failed: bool = False  # whether a failure happened in the episode so far


@dataclass
class Counters:
    """Totals of a model's life."""

    steps: int = 0
    episodes: int = 0
    model_version: int = 0
    interventions: dict[str, int] = field(default_factory=dict)
    failures: dict[str, int] = field(default_factory=dict)  # events learned, per criterion
    streams_expired: int = 0  # streams forgotten to stay within max_streams
