"""The risk reviser's decision (``reviser.method: risk``): the monotone prior and the choice.

The paper flags *states* where a failure was seen and steers away from them. That attaches a
failure to the wrong thing: a crash in a state happened under an action, and braking there a
thousand times without a crash says nothing about accelerating there. The risk reviser instead
estimates, per action, the probability of each failure within a horizon
(:mod:`app.core.local_risk`), and decides here:

* **Monotone prior.** Each criterion has a safe direction: braking harder never raises the risk
  of a collision, speeding up never raises the risk of falling behind. So the risk of an action
  is at least that of every action on its safe side: the risks over the action bins are lifted
  to their running maximum from the safe end of the action range.
* **The decision.** The proposal is kept when its total risk is under an absolute threshold or
  within a margin of the safest action's; otherwise the allowed action nearest to it is applied.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt
from numba import njit

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]


def safe_steps(directions: Sequence[str]) -> IntArray:
    """Per criterion, the way along the action bins that never raises its risk: -1 where
    slower is safer (``decrease``), +1 where faster is (``increase``)."""
    return np.array([-1 if d == "decrease" else 1 for d in directions], dtype=np.int64)


@njit(cache=True)
def monotone(by_bin: FloatArray, safe: IntArray) -> None:
    """Lift ``by_bin`` (actions x criteria), in place, to the running maximum of each
    criterion's risk from its safe end of the action range (``safe`` from :func:`safe_steps`).

    Slower is safer (collision): ``risk(a) >= risk(a')`` for every ``a' < a``; faster is
    safer (falling behind): for every ``a' > a``.
    """
    q, n_c = by_bin.shape
    for c in range(n_c):
        first, last, way = (0, q, 1) if safe[c] < 0 else (q - 1, -1, -1)
        running = by_bin[first, c]
        for a in range(first, last, way):
            value = by_bin[a, c]
            running = value if value > running else running
            by_bin[a, c] = running


@njit(cache=True)
def kept_limit(total: FloatArray, threshold: float, margin: float
               ) -> float:
    """The largest total risk an action may carry and be applied: ``threshold``, or ``margin``
    above the safest action's risk, whichever is higher."""
    least: float = total.min()
    return max(threshold, least + margin)


@njit(cache=True)
def choose(total: FloatArray, proposed_bin: int, limit: float, safe_step: int
           ) -> int:
    """The bin to apply: the proposal when its total risk is within ``limit``
    (:func:`kept_limit`); otherwise the allowed bin nearest to it, ties broken towards
    ``safe_step`` (-1: slower, +1: faster)."""
    if total[proposed_bin] <= limit:
        return proposed_bin
    best, best_distance = -1, 0
    for a in range(total.shape[0]):
        if total[a] <= limit:
            offset = a - proposed_bin
            distance = abs(offset) * 2 - (1 if (offset > 0) - (offset < 0) == safe_step else 0)
            if best < 0 or distance < best_distance:
                best, best_distance = a, distance
    return best


@njit(cache=True)
def decide(by_bin: FloatArray, proposed_bin: int, threshold: float, margin: float,
           safe: IntArray, verdicts: IntArray) -> tuple[float, int, int, bool]:
    """One decision on ``by_bin`` (actions x criteria, the risks after :func:`monotone`):
    ``verdicts`` gets each bin's, -1 within the limit (:func:`kept_limit`), else its riskiest
    criterion (the first of equals). Returns the limit, the proposal's verdict, the bin to
    apply (:func:`choose`, towards the safe side of the proposal's riskiest criterion) and
    whether that is the proposal because it is within the limit."""
    q, n_c = by_bin.shape
    total = np.empty(q)
    for a in range(q):
        total[a] = by_bin[a, 0]
        for c in range(1, n_c):
            total[a] += by_bin[a, c]
    limit = kept_limit(total, threshold, margin)
    for a in range(q):
        worst = 0
        for c in range(1, n_c):
            if by_bin[a, c] > by_bin[a, worst]:
                worst = c
        verdicts[a] = -1 if total[a] <= limit else worst
    kept = total[proposed_bin] <= limit
    worst = verdicts[proposed_bin]
    if kept:
        return limit, worst, proposed_bin, kept
    return limit, worst, choose(total, proposed_bin, limit, safe[worst]), kept
