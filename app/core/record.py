"""The shield's own record: per state, whether its revisions are followed by fewer failures than
the proposals it passed, and where they are not, the shield backs off.

A revision is a claim: *this action is safer than the proposal*. The model behind it can be
wrong where its assumptions fail (a safe direction that holds in one part of the state space
and not in another, a failure that comes later than the horizon), and then the shield makes
the controller worse. So each step the risk reviser decides is kept, with the state it was
recognised in and whether it was revised, until its outcome is known: *failed* when any
failure follows within ``window`` steps, *not failed* once it is older or its episode has
ended without one. Per state this counts:

* ``revised``, ``revised_failed``: the steps it revised, and those a failure followed;
* ``passed``, ``passed_failed``: the steps whose proposal it applied unchanged (before any
  failure was learned, within the margin, or backed off), and those a failure followed;
* ``revised_failures``: the failures (events, not steps) that followed a revision there.

The shield **backs off** in a state, passing the proposal, when its revisions there were
followed by failures at least :data:`MIN_FAILURES` times and their failure rate exceeds the
passed proposals' by more than :data:`Z` standard errors. Its steps are counted as samples of
``window`` steps each (a failure labels all the steps before it within the window, so the
steps of one window are one observation, not many). Backing off is the two-armed comparison
run per state: once the shield passes the proposals there, the passed steps are the
controller's own record in that state, and if passing fails more often than revising did,
the shield revises there again.

Within a state the shield revises the riskier steps, so its revisions would look worse than
the passes even where they help; and where its model is wrong everywhere, no single state
gathers the evidence soon enough. So the record also counts the steps over all states by the
band of the proposal's predicted total risk (:data:`EDGES`), and compares revised and passed
steps *of the same band*, pooled over the bands (:func:`pooled_excess`): where revisions are
followed by failures more often than passed proposals the model judged as risky, by more than
:data:`Z_EVERYWHERE` standard errors, the shield backs off in every state, until passing
fails more often than revising did.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping
from typing import Any

import numpy as np
import numpy.typing as npt

from app.core import _stored as stored
from app.core.errors import InvalidSnapshot

IntArray = npt.NDArray[np.int64]

MIN_FAILURES = 2  # failures after revisions in a state before the shield may back off there
Z = 1.0  # standard errors by which revisions must fail more often than the passed proposals
Z_EVERYWHERE = 2.0  # the same, pooled over every state: backing off everywhere needs more

EDGES = (0.01, 0.05, 0.2, 0.5)  # the bands of the proposal's predicted total risk
REVISED, REVISED_FAILED, PASSED, PASSED_FAILED, REVISED_FAILURES = range(5)
COLUMNS = ("revised", "revised_failed", "passed", "passed_failed", "revised_failures")


class Record:
    """Per state the outcomes of the revised and the passed steps (:data:`COLUMNS`), and each
    stream's steps whose outcome is not known yet (a state and whether it was revised)."""

    def __init__(self, window: int) -> None:
        self.window = window
        self.counts = np.zeros((0, len(COLUMNS)), dtype=np.int64)
        # per band of the proposal's predicted risk, over all states: the first four columns
        self.bands = np.zeros((len(EDGES) + 1, PASSED_FAILED + 1), dtype=np.int64)
        self._pending: dict[str, deque[tuple[int, bool, int]]] = {}
        self._revised_failures = 0  # the failures after revisions, over every state
        self.everywhere = False  # whether the shield backs off in every state

    def add_state(self) -> None:
        """Room for one more state, with nothing counted."""
        self.counts = np.concatenate([self.counts, np.zeros((1, len(COLUMNS)), np.int64)])

    def note(self, stream: str, state: int, revised: bool, risk: float) -> None:
        """A decided step of ``stream`` in ``state`` whose proposal's predicted total risk was
        ``risk``; a pending step older than the window is settled as not failed."""
        pending = self._pending.setdefault(stream, deque())
        pending.append((state, revised, band_of(risk)))
        if len(pending) > self.window:
            old, was_revised, band = pending.popleft()
            self.counts[old, REVISED if was_revised else PASSED] += 1
            self.bands[band, REVISED if was_revised else PASSED] += 1
            self.everywhere = self._backs_off_everywhere()

    def settle(self, stream: str, failed: bool) -> None:
        """The stream's episode ended, by a failure (``failed``) or not: every pending step
        is settled."""
        pending = self._pending.pop(stream, None)
        if not pending:
            return
        hit: set[int] = set()
        for state, revised, band in pending:
            row, by_band = self.counts[state], self.bands[band]
            row[REVISED if revised else PASSED] += 1
            by_band[REVISED if revised else PASSED] += 1
            if failed:
                row[REVISED_FAILED if revised else PASSED_FAILED] += 1
                by_band[REVISED_FAILED if revised else PASSED_FAILED] += 1
                if revised:
                    hit.add(state)
        for state in hit:
            self.counts[state, REVISED_FAILURES] += 1
        self._revised_failures += len(hit)
        self.everywhere = self._backs_off_everywhere()

    def forget(self, stream: str) -> None:
        """Drop a stream's pending steps (a stream the model forgets, unsettled)."""
        self._pending.pop(stream, None)

    def backs_off(self, state: int) -> bool:
        """Whether the revisions in ``state`` are followed by failures more often than the
        proposals passed there, by the test in the module's docstring."""
        if self.everywhere:
            return True
        row = self.counts[state]
        if row[REVISED_FAILURES] < MIN_FAILURES:
            return False
        return (
            excess(
                int(row[REVISED]),
                int(row[REVISED_FAILED]),
                int(row[PASSED]),
                int(row[PASSED_FAILED]),
                self.window,
            )
            > Z
        )

    def _backs_off_everywhere(self) -> bool:
        """Whether, over all states, the revised steps are followed by failures more often
        than the passed ones whose proposals the model judged as risky (the bands of
        :data:`EDGES`), by more than :data:`Z_EVERYWHERE` standard errors
        (:func:`pooled_excess`)."""
        if self._revised_failures < MIN_FAILURES:
            return False
        return pooled_excess(self.bands, self.window) > Z_EVERYWHERE

    def backed_off(self) -> npt.NDArray[np.bool_]:
        """Per state, whether the shield backs off there now."""
        return np.array([self.backs_off(i) for i in range(self.counts.shape[0])], dtype=bool)

    def snapshot(self) -> dict[str, Any]:
        """The counts (per state, and per band of predicted risk), and each stream's pending
        steps (streams named in order, their lengths, then states, whether revised and their
        bands, concatenated)."""
        names = [name for name, pending in self._pending.items() if pending]
        steps = [step for name in names for step in self._pending[name]]
        return {
            "counts": self.counts.copy(),
            "streams": names,
            "lengths": np.array([len(self._pending[n]) for n in names], dtype=np.int64),
            "states": np.array([s for s, _, _ in steps], dtype=np.int64),
            "revised": np.array([r for _, r, _ in steps], dtype=np.int64),
            "bands": self.bands.copy(),
            "risk_bands": np.array([b for _, _, b in steps], dtype=np.int64),
        }

    @classmethod
    def restore(
        cls, window: int, n_states: int, streams: Mapping[str, object], data: dict[str, Any] | None
    ) -> Record:
        """Rebuild from :meth:`snapshot` output, checking every part (None, a snapshot from
        before the record: nothing counted); ``streams`` are the model's streams."""
        self = cls(window)
        self.counts = np.zeros((n_states, len(COLUMNS)), dtype=np.int64)
        if data is None:
            return self
        counts = stored.ints(
            data["counts"], "record.counts", (n_states, len(COLUMNS)), low=0, high=stored.MAX_COUNT
        )
        if (
            (counts[:, REVISED_FAILED] > counts[:, REVISED])
            | (counts[:, PASSED_FAILED] > counts[:, PASSED])
            | (counts[:, REVISED_FAILURES] > counts[:, REVISED_FAILED])
        ).any():
            raise InvalidSnapshot(
                "more failed steps than steps in a state's record", field="record.counts"
            )
        names = data["streams"]
        if (
            not isinstance(names, list)
            or not all(isinstance(s, str) for s in names)
            or len(set(names)) != len(names)
            or not set(names) <= set(streams)
        ):
            raise InvalidSnapshot(
                "pending steps name each of the model's streams at most once",
                field="record.streams",
            )
        lengths = stored.ints(data["lengths"], "record.lengths", (len(names),), low=1, high=window)
        total = int(lengths.sum())
        states = stored.ints(
            data["states"], "record.states", (total,), low=0, high=max(n_states - 1, 0)
        )
        revised = stored.ints(data["revised"], "record.revised", (total,), low=0, high=1)
        # (a snapshot from before the bands: none counted, its pending steps in the lowest)
        bands = stored.ints(
            data.get("bands", np.zeros_like(self.bands)),
            "record.bands",
            self.bands.shape,
            low=0,
            high=stored.MAX_COUNT,
        )
        if (
            (bands[:, REVISED_FAILED] > bands[:, REVISED])
            | (bands[:, PASSED_FAILED] > bands[:, PASSED])
        ).any():
            raise InvalidSnapshot("more failed steps than steps in a band", field="record.bands")
        if bands.any() and not np.array_equal(
            bands.sum(axis=0), counts[:, : PASSED_FAILED + 1].sum(axis=0)
        ):
            raise InvalidSnapshot(
                "the bands count other steps than the states", field="record.bands"
            )
        risk_bands = stored.ints(
            data.get("risk_bands", np.zeros(total, dtype=np.int64)),
            "record.risk_bands",
            (total,),
            low=0,
            high=len(EDGES),
        )
        self.counts, self.bands = counts.copy(), bands.copy()
        self._revised_failures = int(counts[:, REVISED_FAILURES].sum())
        at = 0
        for name, length in zip(names, lengths.tolist(), strict=True):
            self._pending[name] = deque(
                (int(s), bool(r), int(b))
                for s, r, b in zip(
                    states[at : at + length].tolist(),
                    revised[at : at + length].tolist(),
                    risk_bands[at : at + length].tolist(),
                    strict=True,
                )
            )
            at += length
        self.everywhere = self._backs_off_everywhere()
        return self


def band_of(risk: float) -> int:
    """The band of :data:`EDGES` a predicted total risk falls in."""
    band = 0
    while band < len(EDGES) and risk >= EDGES[band]:
        band += 1
    return band


def pooled_excess(bands: IntArray, window: int) -> float:
    """How many standard errors the failure rate after revisions exceeds the one after passed
    proposals of the same band of predicted risk, pooled over the bands with both (a
    Mantel-Haenszel risk difference, each band weighted by ``n_r n_p / (n_r + n_p)``; the rates
    and samples as in :func:`excess`)."""
    weight = difference = variance = 0.0
    for revised, revised_failed, passed, passed_failed in bands.tolist():
        if revised == 0 or passed == 0:
            continue
        rate_r = (revised_failed + 1) / (revised + 2)
        rate_p = (passed_failed + 1) / (passed + 2)
        samples_r, samples_p = max(revised / window, 1.0), max(passed / window, 1.0)
        w = samples_r * samples_p / (samples_r + samples_p)
        weight += w
        difference += w * (rate_r - rate_p)
        variance += w * w * (rate_r * (1 - rate_r) / samples_r + rate_p * (1 - rate_p) / samples_p)
    return 0.0 if weight == 0.0 else difference / math.sqrt(variance)


def excess(
    revised: int, revised_failed: int, passed: int, passed_failed: int, window: int
) -> float:
    """How many standard errors the failure rate after revisions exceeds the one after passed
    proposals (each rate with one failure and one success added, each count in samples of
    ``window`` steps, at least one)."""
    rate_r = (revised_failed + 1) / (revised + 2)
    rate_p = (passed_failed + 1) / (passed + 2)
    samples_r, samples_p = max(revised / window, 1.0), max(passed / window, 1.0)
    error = math.sqrt(rate_r * (1 - rate_r) / samples_r + rate_p * (1 - rate_p) / samples_p)
    return (rate_r - rate_p) / error
