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
  With the reach (:mod:`app.core.reach`) two tables are asked: an action must be allowed by the
  reach, and also by the local model where the two allow an action in common. Where no action
  avoids a failure on its worst path, the allowed action furthest to the safe side applies.
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


@njit(cache=True)
def decide_with_reach(by_bin: FloatArray, reached: FloatArray, proposed_bin: int,
                      threshold: float, margin: float, safe: IntArray, verdicts: IntArray
                      ) -> tuple[float, int, int, bool]:
    """One decision on two tables (actions x criteria, both after :func:`monotone`): the
    local model's risks (``by_bin``) and the reach's (``reached``). The reach decides first:
    a failure that the safest continuation cannot avoid any more outranks what followed the
    action before. A bin is allowed when its reach is within the reach's limit and, where some
    bin is within both limits, its risk within the local one (:func:`kept_limit` each).

    ``verdicts`` gets each bin's: -1 allowed, else the riskiest criterion of the table that
    refused it (the reach's first); ``by_bin`` becomes the larger of the two, what the
    decision record shows. Returns the limit of the table that refused the proposal (the
    local one's when it was kept), the proposal's verdict, the bin to apply and whether that
    is the proposal. The bin applied is the proposal when allowed, else the nearest allowed
    bin (:func:`choose`, towards the safe side of the proposal's riskiest criterion); but
    when no bin's reach is within the threshold (a failure that no action avoids on its worst
    path), the allowed bin furthest to the safe side of the criterion the proposal's reach
    risks most, the proposal only when it is that bin: braking as hard as allowed rather
    than as little as the reach's margin allows, which its crossing times, all close to each
    other there, cannot tell apart."""
    q, n_c = by_bin.shape
    local, far = np.empty(q), np.empty(q)
    for a in range(q):
        local[a], far[a] = by_bin[a, 0], reached[a, 0]
        for c in range(1, n_c):
            local[a] += by_bin[a, c]
            far[a] += reached[a, c]
    limit_local = kept_limit(local, threshold, margin)
    limit_far = kept_limit(far, threshold, margin)
    both = False
    for a in range(q):
        both = both or (far[a] <= limit_far and local[a] <= limit_local)
    refused = np.zeros(q)  # 0 allowed, 1 refused: what choose picks from
    for a in range(q):
        table = reached if far[a] > limit_far else by_bin
        if far[a] > limit_far or (both and local[a] > limit_local):
            worst = 0
            for c in range(1, n_c):
                if table[a, c] > table[a, worst]:
                    worst = c
            verdicts[a], refused[a] = worst, 1.0
        else:
            verdicts[a] = -1
        for c in range(n_c):
            by_bin[a, c] = max(by_bin[a, c], reached[a, c])
    limit = limit_far if far[proposed_bin] > limit_far else limit_local
    worst = verdicts[proposed_bin]
    if far.min() > threshold:
        # no bin keeps clear of a failure on its worst path: the allowed bin furthest to the
        # safe side of the criterion the proposal risks most puts the failure off the longest
        riskiest = 0
        for c in range(1, n_c):
            if reached[proposed_bin, c] > reached[proposed_bin, riskiest]:
                riskiest = c
        for a in range(q - 1, -1, -1) if safe[riskiest] > 0 else range(q):
            if refused[a] == 0.0:
                if a == proposed_bin:
                    return limit, worst, a, True
                return limit, riskiest if worst < 0 else worst, a, False
    if worst < 0:
        return limit, worst, proposed_bin, True
    return limit, worst, choose(refused, proposed_bin, 0.0, safe[worst]), False
