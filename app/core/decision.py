"""The decision record of one step (docs/api.md, "The decision record"): what a reviser
answers, and the actions it passed over."""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, overload

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]


@dataclass(slots=True)
class Candidate:
    """An action the reviser inspected: the bin's action (the paper's reviser: its midpoint;
    the risk reviser: the midpoint, the range's end for an end bin), the bin, its verdict and
    (for the risk reviser) its risk per criterion."""

    action: float
    bin: int
    verdict: str
    risk: dict[str, float] | None = None


class RiskCandidates(Sequence[Candidate]):
    """The bins the risk reviser passed over, from the proposal's neighbour to the bin
    applied, built on first use from the step's risk and verdict per bin (most callers never
    read them). ``bin_actions`` are the bins' actions and ``verdicts_named`` the criteria's
    names then ``"ok"``, so that a verdict (-1: ok) indexes its name."""

    def __init__(
        self,
        bins: range,
        by_bin: FloatArray,
        verdicts: npt.NDArray[np.int64],
        names: Sequence[str],
        bin_actions: Sequence[float],
        verdicts_named: Sequence[str],
    ) -> None:
        self._bins, self._by_bin, self._verdicts = bins, by_bin, verdicts
        self._names, self._actions, self._verdicts_named = names, bin_actions, verdicts_named
        self._built: tuple[Candidate, ...] | None = None

    def _all(self) -> tuple[Candidate, ...]:
        if self._built is None:
            self._built = tuple(Candidate(**record) for record in self.records())
        return self._built

    def records(self) -> list[dict[str, Any]]:
        """The candidates as JSON-able records (what :meth:`Decision.to_dict` writes), made
        straight from the arrays: the service's per-step path."""
        names, rows, verdicts = self._names, self._by_bin.tolist(), self._verdicts.tolist()
        bin_actions, named = self._actions, self._verdicts_named
        return [
            {
                "action": bin_actions[r],
                "bin": r,
                "verdict": named[verdicts[r]],
                "risk": {name: risk for name, risk in zip(names, rows[r], strict=True)},
            }
            for r in self._bins
        ]  # (a comprehension builds a small dict faster than dict())

    def __iter__(self) -> Iterator[Candidate]:
        return iter(self._all())

    @overload
    def __getitem__(self, i: int) -> Candidate: ...
    @overload
    def __getitem__(self, i: slice) -> tuple[Candidate, ...]: ...

    def __getitem__(self, i: int | slice) -> Candidate | tuple[Candidate, ...]:
        return self._all()[i]

    def __len__(self) -> int:
        return len(self._bins)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Sequence) and self._all() == tuple(other)

    def __repr__(self) -> str:
        return repr(self._all())


@dataclass(slots=True)
class Decision:
    """The decision record of one step (docs/api.md). Built on every step, so a plain slotted
    record: a frozen dataclass's constructor costs about three times as much."""

    action: float | None
    proposed: float | None
    revised: bool
    reason: str
    verdict: str
    risk: dict[str, float]
    threshold: float | None
    candidates: Sequence[Candidate]
    state: int | None
    n_states: int
    new_state: bool
    episode: int
    step: int
    model_version: int
    stream: str
    shadow: bool = False
    suggested: float | None = None

    def to_dict(self) -> dict[str, Any]:
        """JSON-able data, written out by hand: this is on the service's per-step path."""
        return {
            "action": self.action,
            "proposed": self.proposed,
            "revised": self.revised,
            "reason": self.reason,
            "verdict": self.verdict,
            "risk": self.risk,
            "threshold": self.threshold,
            "candidates": (
                self.candidates.records()
                if isinstance(self.candidates, RiskCandidates)
                else [
                    {"action": c.action, "bin": c.bin, "verdict": c.verdict, "risk": c.risk}
                    for c in self.candidates
                ]
            ),
            "state": self.state,
            "n_states": self.n_states,
            "new_state": self.new_state,
            "episode": self.episode,
            "step": self.step,
            "model_version": self.model_version,
            "stream": self.stream,
            "shadow": self.shadow,
            "suggested": self.suggested,
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Decision:
        """The inverse of :meth:`to_dict`."""
        fields = dict(data)
        fields["candidates"] = tuple(Candidate(**c) for c in data["candidates"])
        return cls(**fields)
