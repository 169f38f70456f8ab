"""Unfavourable-state flags L(s(i)), visit, entry and failure counts (docs/algorithm.md).

A flag is 0 (l_n, favourable) or ``1 + c`` for criterion ``c`` of the configuration, whose
order is the priority (the paper: collision l_s before large distance l_ld).
"""

from __future__ import annotations

from typing import Any, Literal

import numpy as np
import numpy.typing as npt
from numba import njit

from app.core import _stored as stored
from app.core._arrays import ensure_capacity, read_only
from app.core.errors import InvalidSnapshot

IntArray = npt.NDArray[np.int64]
FlagMode = Literal["overwrite", "rate"]
NO_FLAG = 0
FLAG, VISITS, ENTRIES = range(3)  # the rows of StateFlags.table


class StateFlags:
    """The flag, the number of recognitions and entries and the failures of every state:
    ``table`` (flag, visits and entries, one row each, per state) and ``failures`` (states x
    criteria), arrays a compiled step takes whole."""

    def __init__(self, mode: FlagMode, max_states: int, n_criteria: int, min_rate: float) -> None:
        self.mode = mode
        self.max_states = max_states
        self.min_rate = min_rate
        self._n = 0
        self.table = np.zeros((3, 0), dtype=np.int64)
        self._failures = np.zeros((0, n_criteria), dtype=np.int64)
        self._flagged: tuple[IntArray, IntArray] | None = None
        self._arrays: tuple[IntArray, IntArray, bool, float] | None = None  # see arrays

    @property
    def flags(self) -> npt.NDArray[np.int64]:
        """Flag of every state (read-only)."""
        return read_only(self.table[FLAG, : self._n])

    @property
    def visits(self) -> npt.NDArray[np.int64]:
        """How often each state was the recognised one (read-only view)."""
        return read_only(self.table[VISITS, : self._n])

    @property
    def entries(self) -> npt.NDArray[np.int64]:
        """How often a stream came into each state from another one, or began there
        (read-only view)."""
        return read_only(self.table[ENTRIES, : self._n])

    def arrays(self) -> tuple[IntArray, IntArray, bool, float]:
        """What a compiled step counts in (:func:`observe`'s arrays and settings, in order):
        the same tuple until a state is added."""
        if self._arrays is None:
            self._arrays = (self.table, self._failures, self.mode == "rate", self.min_rate)
        return self._arrays

    @property
    def failures(self) -> npt.NDArray[np.int64]:
        """Failures of each criterion recognised in each state, n x criteria (read-only)."""
        return read_only(self._failures[: self._n])

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
        self.table = ensure_capacity(self.table, n + 1, self.max_states, axis=1)
        self._failures = ensure_capacity(self._failures, n + 1, self.max_states)
        self._arrays = None
        self._n = n + 1

    def observe(self, state: int, criterion: int | None, entered: bool) -> None:
        """Count a recognition of ``state`` (an entry too, if ``entered``; and its failure, if
        any) and flag it (A4).

        ``overwrite``: the literal re-flagging of the recognised state on every step.
        ``rate`` (A4 c, count-based): the state carries the highest-priority criterion whose
        failures make up at least ``min_rate`` of the entries into it, so that a state which
        covers much ordinary driving is not condemned by one failure at its edge, and one where
        cars wait for minutes per visit does not dilute the failures that end there.
        """
        if observe(
            self.table,
            self._failures,
            state,
            -1 if criterion is None else criterion,
            entered,
            self.mode == "rate",
            self.min_rate,
        ):
            self.changed()

    def changed(self) -> None:
        """A flag changed (in :func:`observe`): the flagged states are found again."""
        self._flagged = None

    def snapshot(self) -> dict[str, Any]:
        """Exact state."""
        return {
            "flags": self.flags.copy(),
            "visits": self.visits.copy(),
            "entries": self.entries.copy(),
            "failures": self.failures.copy(),
        }

    @classmethod
    def restore(
        cls, mode: FlagMode, max_states: int, n_criteria: int, min_rate: float, data: dict[str, Any]
    ) -> StateFlags:
        """Rebuild from :meth:`snapshot` output. Snapshots from before entries were counted
        lack them: they count from the restore on."""
        self = cls(mode, max_states, n_criteria, min_rate)
        flags = stored.ints(data["flags"], "flags.flags", high=n_criteria).ravel()
        n = self._n = flags.shape[0]
        if n > max_states:
            raise InvalidSnapshot(f"more than {max_states} states", field="flags.flags")
        self.table = np.stack(
            [
                flags,
                stored.ints(data["visits"], "flags.visits", (n,)),
                _counts(data.get("entries"), "flags.entries", n),
            ]
        )
        self._failures = stored.ints(data["failures"], "flags.failures", (n, n_criteria))
        return self


def _counts(data: Any, field: str, n: int) -> IntArray:
    if data is None:
        return np.zeros(n, dtype=np.int64)
    return stored.ints(data, field, (n,))


@njit(cache=True)
def observe(
    table: IntArray,
    failures: IntArray,
    state: int,
    criterion: int,
    entered: bool,
    rate: bool,
    min_rate: float,
) -> bool:
    """:meth:`StateFlags.observe` on its arrays (``criterion`` -1: none, ``rate``: the rate
    mode); whether the state's flag changed."""
    table[VISITS, state] += 1
    if entered:
        table[ENTRIES, state] += 1
    if criterion >= 0:
        failures[state, criterion] += 1
    old = table[FLAG, state]
    new = NO_FLAG
    if rate:  # a step without failure can lift a flag but never set one
        if criterion >= 0 or old != NO_FLAG:
            least = max(1.0, min_rate * table[ENTRIES, state])
            for c in range(failures.shape[1]):
                if failures[state, c] >= least:
                    new = c + 1
                    break
    elif criterion >= 0:
        new = criterion + 1
    table[FLAG, state] = new
    return bool(new != old)
