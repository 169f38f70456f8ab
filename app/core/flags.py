"""Unfavourable-state flags L(s(i)), visit, entry and failure counts (docs/algorithm.md).

A flag is 0 (l_n, favourable) or ``1 + c`` for criterion ``c`` of the configuration, whose
order is the priority (the paper: collision l_s before large distance l_ld).
"""

from __future__ import annotations

from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from app.core import _stored as stored
from app.core._arrays import ensure_capacity
from app.core.errors import InvalidSnapshot

IntArray = npt.NDArray[np.int64]
FlagMode = Literal["sticky", "overwrite", "rate"]
RatePer = Literal["recognition", "entry"]
NO_FLAG = 0


class StateFlags:
    """The flag, the number of recognitions and entries and the failures of every state.

    With ``failure_centres``, a state whose centre is the observation of a failure carries
    that failure's flag besides the flag of ``mode``, for as long as the centre stays there:
    such a state is where the failure happened, however often it is passed without one.
    """

    def __init__(self, mode: FlagMode, max_states: int, n_criteria: int,
                 min_rate: float, rate_per: RatePer, failure_centres: bool = False) -> None:
        self.mode = mode
        self.max_states = max_states
        self.min_rate = min_rate
        self.rate_per = rate_per
        self.failure_centres = failure_centres
        self._n = 0
        self._flags = np.zeros(0, dtype=np.int64)  # the flags of ``mode`` alone
        self._centres = np.zeros(0, dtype=np.int64)
        self._visits = np.zeros(0, dtype=np.int64)
        self._entries = np.zeros(0, dtype=np.int64)
        self._failures = np.zeros((0, n_criteria), dtype=np.int64)
        self._flagged: tuple[IntArray, IntArray] | None = None

    @property
    def flags(self) -> npt.NDArray[np.int64]:
        """Flag of every state (read-only)."""
        own = self._flags[: self._n]
        if not self.failure_centres:
            return _read_only(own)
        return _read_only(_first(own, self._centres[: self._n]))

    @property
    def centres(self) -> npt.NDArray[np.int64]:
        """Per state, 1 + the criterion of the failure whose observation is its centre, or 0
        (read-only view; kept whether or not ``failure_centres`` flags by it)."""
        return _read_only(self._centres[: self._n])

    @property
    def visits(self) -> npt.NDArray[np.int64]:
        """How often each state was the recognised one (read-only view)."""
        return _read_only(self._visits[: self._n])

    @property
    def entries(self) -> npt.NDArray[np.int64]:
        """How often a stream came into each state from another one, or began there
        (read-only view)."""
        return _read_only(self._entries[: self._n])

    @property
    def failures(self) -> npt.NDArray[np.int64]:
        """Failures of each criterion recognised in each state, n x criteria (read-only)."""
        return _read_only(self._failures[: self._n])

    def flagged(self) -> tuple[IntArray, IntArray]:
        """The flagged states (ascending) and their flags: the reviser reads only these."""
        if self._flagged is None:
            flags = self.flags
            index = np.flatnonzero(flags)
            self._flagged = (index, flags[index])
        return self._flagged

    def add_state(self) -> None:
        """A new state starts favourable and unvisited."""
        n = self._n
        self._flags = ensure_capacity(self._flags, n + 1, self.max_states)
        self._centres = ensure_capacity(self._centres, n + 1, self.max_states)
        self._visits = ensure_capacity(self._visits, n + 1, self.max_states)
        self._entries = ensure_capacity(self._entries, n + 1, self.max_states)
        self._failures = ensure_capacity(self._failures, n + 1, self.max_states)
        self._n = n + 1

    def place_centre(self, state: int, criterion: int | None) -> None:
        """The centre of ``state`` is now an observation: of a failure of ``criterion``, or of
        none."""
        centre = NO_FLAG if criterion is None else criterion + 1
        if centre != self._centres[state]:
            self._centres[state] = centre
            self._flagged = None

    def observe(self, state: int, criterion: int | None, entered: bool) -> None:
        """Count a recognition of ``state`` (an entry too, if ``entered``; and its failure, if
        any) and flag it (A4).

        ``sticky``: an unfavourable flag is only replaced by one of higher priority.
        ``overwrite``: the literal re-flagging of the recognised state on every step.
        ``rate`` (A4 c, count-based): the state carries the highest-priority criterion whose
        failures make up at least ``min_rate`` of its recognitions (or of its entries, by
        ``rate_per``), so that a state which covers much ordinary driving is not condemned by
        one failure at its edge.
        """
        self._visits[state] += 1
        if entered:
            self._entries[state] += 1
        if criterion is not None:
            self._failures[state, criterion] += 1
        old = int(self._flags[state])
        if self.mode == "rate":  # a step without failure can lift a flag but never set one
            new = self._rate_flag(state) if criterion is not None or old else NO_FLAG
        else:
            new = NO_FLAG if criterion is None else criterion + 1
            if self.mode == "sticky" and (new == NO_FLAG or NO_FLAG < old < new):
                new = old
        if new != old:
            self._flags[state] = new
            self._flagged = None

    def _rate_flag(self, state: int) -> int:
        failures = self._failures[state]
        count = self._entries[state] if self.rate_per == "entry" else self._visits[state]
        frequent = np.flatnonzero(failures >= max(1.0, self.min_rate * count))
        return int(frequent[0]) + 1 if frequent.size else NO_FLAG

    def snapshot(self) -> dict[str, Any]:
        """Exact state (``flags``: those of ``mode`` alone)."""
        return {"flags": self._flags[: self._n].copy(), "centres": self.centres.copy(),
                "visits": self.visits.copy(), "entries": self.entries.copy(),
                "failures": self.failures.copy()}

    @classmethod
    def restore(cls, mode: FlagMode, max_states: int, n_criteria: int, min_rate: float,
                rate_per: RatePer, failure_centres: bool, data: dict[str, Any]) -> StateFlags:
        """Rebuild from :meth:`snapshot` output. Snapshots from before entries were counted
        lack them, and those from before failure centres were kept lack these: they count
        from the restore on."""
        self = cls(mode, max_states, n_criteria, min_rate, rate_per, failure_centres)
        self._flags = stored.ints(data["flags"], "flags.flags", high=n_criteria).ravel()
        n = self._n = self._flags.shape[0]
        if n > max_states:
            raise InvalidSnapshot(f"more than {max_states} states", field="flags.flags")
        self._visits = stored.ints(data["visits"], "flags.visits", (n,))
        self._entries = _counts(data.get("entries"), "flags.entries", n)
        self._centres = _counts(data.get("centres"), "flags.centres", n, high=n_criteria)
        self._failures = stored.ints(data["failures"], "flags.failures", (n, n_criteria))
        return self


def _counts(data: Any, field: str, n: int, high: int | None = None) -> IntArray:
    if data is None:
        return np.zeros(n, dtype=np.int64)
    return stored.ints(data, field, (n,), high=high)


def _first(own: IntArray, centres: IntArray) -> IntArray:
    """Per state, the flag of higher priority (lower criterion) of two, 0 where both are."""
    either: IntArray = np.where(own == NO_FLAG, centres,
                                np.where(centres == NO_FLAG, own, np.minimum(own, centres)))
    return either


def _read_only(view: npt.NDArray[np.int64]) -> npt.NDArray[np.int64]:
    view.flags.writeable = False
    return view
