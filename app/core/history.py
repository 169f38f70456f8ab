"""A model's life in numbers, in bounded memory: its running totals as episodes end.

A row holds the model's totals when an episode ended: finished episodes, learning steps,
states, revised actions per criterion and failures (events learned) per criterion. Rows keep
totals, not per-episode counts, so any two rows tell what happened between them (revisions per
episode, the share of revised actions, failures), however far apart they lie. That lets the
history stay bounded and still reach back to the start: a row is kept every ``stride``
episodes, and when ``limit`` rows are held every other one is dropped and the stride doubles,
so at most ``limit`` rows span the whole life at even spacing.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from app.core import _stored as stored
from app.core._arrays import ensure_capacity, read_only
from app.core.errors import InvalidSnapshot

IntArray = npt.NDArray[np.int64]
LIMIT = 512  # rows kept: 512 x (3 + 2 per criterion) int64, 28 KiB with two criteria
EPISODES, STEPS, N_STATES = 0, 1, 2  # the first columns; then revisions, then failures
TOTALS = 3  # columns before the per-criterion ones


class History:
    """The rows of totals of one model, the latest last.

    >>> h = History(n_criteria=1, limit=4)
    >>> for episode in range(1, 6):
    ...     h.record([episode, 10 * episode, 3, episode // 2, 1])
    >>> h.stride, h.rows[:, EPISODES].tolist()
    (2, [2, 4])
    """

    def __init__(self, n_criteria: int, limit: int = LIMIT) -> None:
        if limit < 4:
            raise ValueError("a history keeps at least 4 rows")
        self.limit = limit
        self.stride = 1
        self._columns = TOTALS + 2 * n_criteria
        self._rows: IntArray = np.zeros((0, self._columns), dtype=np.int64)
        self._n = 0

    @property
    def rows(self) -> IntArray:
        """rows x (episodes, steps, states, revisions per criterion, failures per criterion)."""
        return read_only(self._rows[: self._n])

    def record(self, totals: Sequence[int]) -> None:
        """Keep the totals at the end of an episode (``totals[EPISODES]`` episodes finished)
        if that episode falls on the stride."""
        if totals[EPISODES] % self.stride:
            return
        while self._n == self.limit:
            self._thin()
            if totals[EPISODES] % self.stride:
                return
        self._rows = ensure_capacity(self._rows, self._n + 1, self.limit)
        self._rows[self._n] = totals
        self._n += 1

    def _thin(self) -> None:
        """Double the stride: keep only the rows that fall on it."""
        self.stride *= 2
        kept = self._rows[: self._n][self._rows[: self._n, EPISODES] % self.stride == 0]
        self._n = kept.shape[0]
        self._rows[: self._n] = kept

    def snapshot(self) -> dict[str, Any]:
        return {"stride": self.stride, "rows": self.rows.copy()}

    @classmethod
    def restore(
        cls, n_criteria: int, data: dict[str, Any], latest: Sequence[int], limit: int = LIMIT
    ) -> History:
        """A history from :meth:`snapshot`'s data, checked: at most ``limit`` rows of totals
        that never decrease, on the stride, none beyond the model's ``latest`` totals."""
        self = cls(n_criteria, limit)
        stride = stored.integer(data["stride"], "history.stride", low=1, high=2**62)
        if stride & (stride - 1):
            raise InvalidSnapshot("the stride is a power of two", field="history.stride")
        raw = data["rows"]
        k = np.shape(raw)[0] if np.ndim(raw) == 2 else -1
        if not 0 <= k <= limit:
            raise InvalidSnapshot(
                f"expected at most {limit} rows of {self._columns} totals", field="history.rows"
            )
        rows = stored.ints(raw, "history.rows", (k, self._columns))
        if k:
            if (np.diff(rows, axis=0) < 0).any() or (np.diff(rows[:, EPISODES]) == 0).any():
                raise InvalidSnapshot(
                    "a row's totals are below the row before it", field="history.rows"
                )
            if (rows[:, EPISODES] % stride).any() or (rows[:, EPISODES] == 0).any():
                raise InvalidSnapshot(
                    f"a row ends an episode off the stride {stride}", field="history.rows"
                )
            if (rows[-1] > np.asarray(latest)).any():
                raise InvalidSnapshot(
                    "the last row's totals exceed the model's counters", field="history.rows"
                )
        self.stride = stride
        self._rows = rows.copy()
        self._n = k
        return self
