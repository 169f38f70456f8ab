"""Unfavourable-state flags L(s(i)) and visit counts (spec §5).

A flag is 0 (l_n, favourable) or ``1 + c`` for criterion ``c`` of the configuration, whose
order is the priority (the paper: collision l_s before large distance l_ld).
"""

from __future__ import annotations

from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from app.core._arrays import ensure_capacity

IntArray = npt.NDArray[np.int64]
NO_FLAG = 0


class StateFlags:
    """The flag and the number of recognitions of every state."""

    def __init__(self, mode: Literal["sticky", "overwrite"], max_states: int) -> None:
        self.mode = mode
        self.max_states = max_states
        self._n = 0
        self._flags = np.zeros(0, dtype=np.int64)
        self._visits = np.zeros(0, dtype=np.int64)
        self._flagged: tuple[IntArray, IntArray] | None = None

    @property
    def flags(self) -> npt.NDArray[np.int64]:
        """Flag of every state (read-only view)."""
        view = self._flags[: self._n]
        view.flags.writeable = False
        return view

    @property
    def visits(self) -> npt.NDArray[np.int64]:
        """How often each state was the recognised one (read-only view)."""
        view = self._visits[: self._n]
        view.flags.writeable = False
        return view

    def flagged(self) -> tuple[IntArray, IntArray]:
        """The flagged states (ascending) and their flags: the reviser reads only these."""
        if self._flagged is None:
            index = np.flatnonzero(self._flags[: self._n])
            self._flagged = (index, self._flags[index])
        return self._flagged

    def add_state(self) -> None:
        """A new state starts favourable and unvisited."""
        self._flags = ensure_capacity(self._flags, self._n + 1, self.max_states)
        self._visits = ensure_capacity(self._visits, self._n + 1, self.max_states)
        self._n += 1

    def observe(self, state: int, criterion: int | None) -> None:
        """Count a recognition of ``state`` and flag it (A4).

        ``sticky`` [REC]: an unfavourable flag is only replaced by one of higher priority.
        ``overwrite``: the literal re-flagging of the recognised state on every step.
        """
        self._visits[state] += 1
        new = NO_FLAG if criterion is None else criterion + 1
        old = self._flags[state]
        if self.mode == "overwrite" or (new != NO_FLAG and (old == NO_FLAG or new < old)):
            self._flags[state] = new
            if new != old:
                self._flagged = None

    def snapshot(self) -> dict[str, Any]:
        """Exact state."""
        return {"flags": self.flags.copy(), "visits": self.visits.copy()}

    @classmethod
    def restore(
        cls, mode: Literal["sticky", "overwrite"], max_states: int, data: dict[str, Any]
    ) -> StateFlags:
        """Rebuild from :meth:`snapshot` output."""
        self = cls(mode, max_states)
        self._flags = np.array(data["flags"], dtype=np.int64).ravel()
        self._visits = np.array(data["visits"], dtype=np.int64).ravel()
        self._n = self._flags.shape[0]
        return self
