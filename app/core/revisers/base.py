"""What every reviser is to the shield that drives it (:class:`app.core.shield.Shield`).

A reviser answers a proposal from the e-FSM it belongs to. The shield clusters the observation,
recognises the belief, learns the transitions and the flags, and calls its reviser at fixed
points of a step; a reviser keeps whatever else it learns (its own models, per state and per
stream), stores it in the model's snapshot and shows it in the model's views. The hooks a
reviser has no use for are no-ops here, so a new reviser is one subclass that says how it
decides (:meth:`Reviser.decide`, :meth:`Reviser.what_if`), one entry in
:data:`app.core.revisers.REVISERS` and its name among ``reviser.method``'s values.

A reviser that decides inside the compiled step (:attr:`Reviser.compiled`) hands the step its
arrays as one tuple (:meth:`Reviser.step_arrays`, :func:`app.core.step.learn_and_decide`'s
``model``) and reads the step's outcome (:class:`app.core.step.Learned`); one that decides in
Python hands it empty arrays of the same types, never read.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from app.core.belief import Belief
from app.core.decision import Decision
from app.core.local_risk import LocalRisk
from app.core.record import COLUMNS as RECORD_COLUMNS
from app.core.stream import StepInput, StreamState
from app.core.trial import Trial

if TYPE_CHECKING:
    from app.core.shield import Shield
    from app.core.step import Learned

FloatArray = npt.NDArray[np.float64]
# the compiled step's reviser tuple for a reviser that decides in Python: types only
_NO_MODEL = (LocalRisk(1, 1, 1, 1, 1, 1, 1).arrays(), np.zeros(0, dtype=np.int64), 0.0, 0.0)


class Reviser:
    """A reviser of the e-FSM ``shield``: the hooks of a step, its snapshot and its views."""

    compiled = False  # whether it decides in the compiled step (:meth:`step_arrays`)

    def __init__(self, shield: Shield) -> None:
        self.shield = shield
        self.names = tuple(c.name for c in shield.config.criteria)

    def no_risk(self) -> dict[str, float]:
        """Every criterion's risk where none is known."""
        return dict.fromkeys(self.names, 0.0)

    # --- a step ----------------------------------------------------------------------------

    def step_arrays(self) -> tuple[Any, ...]:
        """What the compiled step decides with: the same tuple until the reviser's arrays
        change (a state added, a stream's slot reserved)."""
        return _NO_MODEL

    def outputs(self) -> tuple[FloatArray, npt.NDArray[np.int64]]:
        """Fresh arrays for a compiled decision's risk per bin and criterion and verdict per
        bin (a decision record reads them later, so each decision has its own)."""
        q = self.shield.config.action.n_bins
        return np.empty((q, len(self.names))), np.empty(q, dtype=np.int64)

    def begin(self, step: StepInput, state: StreamState) -> None:
        """A learning step of ``state``'s stream starts (before anything is learned)."""

    def decide(
        self,
        step: StepInput,
        state: StreamState,
        belief: Belief,
        z: FloatArray,
        recognised: int,
        new_state: bool,
        learned: Learned,
    ) -> Decision:
        """The decision on a learning step's proposal at ``z`` (the clustering space), the
        model having learned the step (``learned``, the compiled step's outcome): sets the bin
        the stream applied (``state.applied_bin``)."""
        raise NotImplementedError

    def what_if(
        self, step: StepInput, state: StreamState, belief: Belief, z: FloatArray
    ) -> Decision:
        """The decision on a proposal without learning or changing anything (``learn=False``)."""
        raise NotImplementedError

    def end_episode(self, state: StreamState) -> None:
        """``state``'s stream ended an episode."""

    # --- the model's tables ----------------------------------------------------------------

    def add_state(self) -> None:
        """The e-FSM made a state: every table kept per state grows by one."""

    def reserve(self, slot: int) -> None:
        """A stream took ``slot``: room for what is kept per stream."""

    def forget(self, stream: str, slot: int) -> None:
        """The stream ``stream`` in ``slot`` ended or expired: drop what is kept of it."""

    # --- snapshot --------------------------------------------------------------------------

    def snapshot(self) -> dict[str, Any]:
        """The reviser's part of the model's snapshot (keys beside the e-FSM's): every
        snapshot holds the keys of every reviser, null where this one keeps nothing, so that
        its layout does not depend on the configuration."""
        return {"rng": None, "local_risk": None, "record": None, "trial": None}

    def restore(self, data: dict[str, Any]) -> None:
        """Take its part back from a snapshot (:meth:`snapshot`'s keys), checked, into a
        reviser of a shield whose e-FSM and streams are restored already."""

    def counted(self) -> list[tuple[str, float]]:
        """Its counts that no more learning steps than the model's can have made, by the
        snapshot field that holds them (checked on restore)."""
        return []

    # --- views -----------------------------------------------------------------------------

    def record_counts(self) -> npt.NDArray[np.int64]:
        """Its own record per state (:data:`app.core.record.COLUMNS`): none kept here."""
        return np.zeros((self.shield.n_states, len(RECORD_COLUMNS)), dtype=np.int64)

    def backed_off(self) -> npt.NDArray[np.bool_]:
        """Per state, whether it passes proposals there because its revisions did not help."""
        return np.zeros(self.shield.n_states, dtype=bool)

    def backs_off(self, state: int) -> bool:
        """Whether it passes proposals in ``state`` because its revisions did not help."""
        return False

    def failure_points(self, criterion: int) -> FloatArray:
        """Where the failures of ``criterion`` were kept, in the clustering space: none."""
        return np.zeros((0, self.shield.space.size))

    def trial_view(self) -> dict[str, dict[str, int]]:
        """Its trial of itself (:mod:`app.core.trial`): nothing counted."""
        return Trial(0).view()
