"""The transitions behind the outcome counts, kept so that they can be counted again as the
states evolve.

A transition is counted under the state recognised when it happened. eTS+ keeps creating,
moving and widening states, so a count stays with a state index that may since cover another
place: in the first episodes a handful of states cover everything, and a collision counted
then in a broad state stays on that state after finer states have taken the close range over
and it has come to mean following 50 m back. The risk reviser then reads a collision risk there
and brakes a car that is falling behind (docs/risk-reviser.md, "Counts that follow the
states").

The log keeps the latest transitions in the clustering space (the observation before, the
applied action bin, the observation after or the failure) and :meth:`OutcomeLog.recount`
counts them again under the current states: at growing intervals (each time the log has grown
by as much as it held at the last recount), so that the work stays a small multiple of the
steps' own recognition. Beyond ``capacity`` the older half is counted one last time and kept
only as counts (the base), where that recount put it.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import numpy.typing as npt

from app.core import _stored as stored
from app.core._arrays import ensure_capacity
from app.core.errors import InvalidSnapshot
from app.core.risk import OutcomeCounts

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
MostLikely = Callable[[FloatArray], IntArray]  # normalised observations -> states

FIRST_RECOUNT = 1024  # transitions logged before the first recount
MOVE = -1  # the outcome of a transition that led to a state, not to a failure


class OutcomeLog:
    """The last ``capacity`` transitions (0: none kept, the counts are never redone) and the
    counts of the older ones (``base``)."""

    def __init__(self, dim: int, n_actions: int, n_criteria: int, max_states: int,
                 capacity: int) -> None:
        self.dim = dim
        self.capacity = capacity
        self.base = OutcomeCounts(n_actions, n_criteria, max_states)
        self._before = np.zeros((0, dim))
        self._after = np.zeros((0, dim))
        self._bins = np.zeros(0, dtype=np.int64)
        self._outcomes = np.zeros(0, dtype=np.int64)  # MOVE, or the criterion that failed
        self._m = 0
        self._added = 0  # transitions logged since the last recount
        self._due_after = FIRST_RECOUNT

    def __len__(self) -> int:
        return self._m

    @property
    def full(self) -> bool:
        """Whether the next transition needs a recount first (to make room)."""
        return 0 < self.capacity <= self._m

    @property
    def due(self) -> bool:
        """Whether the log has grown enough since the last recount for another."""
        return self.capacity > 0 and self._added >= self._due_after

    @property
    def n_failures(self) -> int:
        """Logged transitions that ended in a failure."""
        return int((self._outcomes[: self._m] != MOVE).sum())

    def add_state(self) -> None:
        """A new state starts with no counts in the base either."""
        self.base.add_state()

    def append(self, before: FloatArray, action_bin: int, after: FloatArray | None,
               criterion: int | None) -> None:
        """One transition: ``action_bin`` applied at ``before`` led to ``after``, or (with
        ``after`` None) to the failure of ``criterion``. The caller recounts first when
        :attr:`full`."""
        if self.capacity == 0:
            return
        at = self._m
        if at == self._bins.shape[0]:  # grow every column, doubling up to the bound
            self._before = ensure_capacity(self._before, at + 1, self.capacity)
            self._after = ensure_capacity(self._after, at + 1, self.capacity)
            self._bins = ensure_capacity(self._bins, at + 1, self.capacity)
            self._outcomes = ensure_capacity(self._outcomes, at + 1, self.capacity)
        self._before[at] = before
        if after is not None:
            self._after[at] = after
        self._bins[at] = action_bin
        self._outcomes[at] = MOVE if criterion is None else criterion
        self._m = at + 1
        self._added += 1

    def recount(self, most_likely: MostLikely, version: int) -> OutcomeCounts:
        """The counts of every transition under the current states: the base plus the log,
        each logged transition under the states ``most_likely`` finds for its observations
        now. A full log first moves its older half into the base."""
        if self.full:
            half = (self._m + 1) // 2
            self.base = self._merged(self.base, most_likely, slice(0, half))
            keep = slice(half, self._m)
            for name in ("_before", "_after", "_bins", "_outcomes"):
                array = getattr(self, name)
                array[: self._m - half] = array[keep].copy()
            self._m -= half
        counts = self._merged(self.base, most_likely, slice(0, self._m))
        counts.version = version
        self._added = 0
        self._due_after = max(FIRST_RECOUNT, self._m)
        return counts

    def _merged(self, base: OutcomeCounts, most_likely: MostLikely, part: slice
                ) -> OutcomeCounts:
        """``base`` plus the logged transitions in ``part`` counted under the current states."""
        n, q, n_c = base.n_states, base.n_actions, base.n_criteria
        bins, outcomes = self._bins[part], self._outcomes[part]
        before = self._before[part]
        states = most_likely(before)
        tries = base.tries + np.bincount(states * q + bins, minlength=n * q).reshape(n, q)
        failed = outcomes != MOVE
        failures = base.failures + np.bincount(
            (states[failed] * q + bins[failed]) * n_c + outcomes[failed],
            minlength=n * q * n_c).reshape(n, q, n_c)
        moved = ~failed
        rows, cols, moves = base.moves()
        keys = np.concatenate([rows * n + cols,
                               (states[moved] * q + bins[moved]) * n
                               + self._states_after(before, states, part, moved, most_likely)])
        weights = np.concatenate([moves, np.ones(int(moved.sum()), dtype=np.int64)])
        unique, inverse = np.unique(keys, return_inverse=True)
        totals = np.bincount(inverse, weights=weights, minlength=unique.size).astype(np.int64)
        return OutcomeCounts.from_arrays(q, n_c, base.max_states, tries, failures,
                                         unique // n, unique % n, totals, base.version)

    def _states_after(self, before: FloatArray, states: IntArray, part: slice,
                      moved: npt.NDArray[np.bool_], most_likely: MostLikely) -> IntArray:
        """The states of the observations after the moves in ``part``. A stream's next
        transition starts where its last one ended, so an observation after equal to the next
        row's observation before takes that row's state instead of being recognised again
        (about half the recount's work when one stream fills the log)."""
        after = self._after[part]
        linked = np.zeros(after.shape[0], dtype=np.bool_)
        linked[:-1] = (after[:-1] == before[1:]).all(axis=1)
        out = np.empty(after.shape[0], dtype=np.int64)
        out[:-1][linked[:-1]] = states[1:][linked[:-1]]
        alone = moved & ~linked
        if alone.any():
            out[alone] = most_likely(after[alone])
        result: IntArray = out[moved]
        return result

    def snapshot(self) -> dict[str, Any]:
        """Exact state as arrays."""
        m = self._m
        return {"before": self._before[:m].copy(), "after": self._after[:m].copy(),
                "bins": self._bins[:m].copy(), "outcomes": self._outcomes[:m].copy(),
                "added": self._added, "due_after": self._due_after,
                "base": self.base.snapshot()}

    @classmethod
    def restore(cls, dim: int, n_actions: int, n_criteria: int, max_states: int,
                capacity: int, data: dict[str, Any], field: str) -> OutcomeLog:
        """Rebuild from :meth:`snapshot` output, checking every part."""
        self = cls(dim, n_actions, n_criteria, max_states, capacity)
        bins = stored.ints(data["bins"], f"{field}.bins", high=n_actions - 1).ravel()
        m = bins.size
        if m > capacity:
            raise InvalidSnapshot(f"the log holds {m} transitions, more than {capacity}",
                                  field=f"{field}.bins")
        self._bins = bins
        self._outcomes = stored.ints(data["outcomes"], f"{field}.outcomes", (m,), low=MOVE,
                                     high=n_criteria - 1)
        self._before = stored.floats(data["before"], f"{field}.before", (m, dim))
        self._after = stored.floats(data["after"], f"{field}.after", (m, dim))
        self._m = m
        self._added = stored.integer(data["added"], f"{field}.added")
        self._due_after = stored.integer(data["due_after"], f"{field}.due_after")
        self.base = OutcomeCounts.restore(n_actions, n_criteria, max_states, data["base"])
        return self
