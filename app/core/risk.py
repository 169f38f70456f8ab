"""The risk reviser's decision (``reviser.method: risk``): one choice over the total risk.

The paper flags *states* where a failure was seen and steers away from them. That attaches a
failure to the wrong thing: a crash in a state happened under an action, and braking there a
thousand times without a crash says nothing about accelerating there. The risk reviser instead
estimates, per action, the probability of each failure within a horizon
(:mod:`app.core.local_risk`), and decides here:

* **Monotone prior.** A criterion declared with a safe direction (braking harder never raises
  the risk of a collision) lifts its risks over the action bins to their running maximum from
  the safe end of the action range. A criterion declared without one keeps its risks as
  learned.
* **One table.** Each action's risk of a criterion blends the two estimates the model has:
  what followed the action before (the local model) and whether a failure can still be avoided
  after it (the reach, :mod:`app.core.reach`), their mean; the action's *total risk* is the
  probability that any failure follows, ``1 - prod_c (1 - risk_c)``. No criterion outranks
  another, and neither estimate outranks the other.
* **The decision.** The proposal is kept when its total risk is within ``margin`` of the least
  total risk of any action (or under ``threshold``); otherwise the action nearest to the
  proposal among those within that limit is applied, the less risky of two equally near.
  Where no action is safe, the limit still holds the least risky: the shield never applies
  an extreme action by rule.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt
from numba import njit

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]


def safe_steps(directions: Sequence[str | None]) -> IntArray:
    """Per criterion, the way along the action bins that never raises its risk: -1 where
    slower is safer (``decrease``), +1 where faster is (``increase``), 0 where no direction
    was declared."""
    steps = {"decrease": -1, "increase": 1, None: 0}
    return np.array([steps[d] for d in directions], dtype=np.int64)


@njit(cache=True)
def monotone(by_bin: FloatArray, safe: IntArray) -> None:
    """Lift ``by_bin`` (actions x criteria), in place, to the running maximum of each
    criterion's risk from its safe end of the action range (``safe`` from :func:`safe_steps`;
    a criterion without a direction, 0, is left as it is).

    Slower is safer (collision): ``risk(a) >= risk(a')`` for every ``a' < a``; faster is
    safer (falling behind): for every ``a' > a``.
    """
    q, n_c = by_bin.shape
    for c in range(n_c):
        if safe[c] == 0:
            continue
        first, last, way = (0, q, 1) if safe[c] < 0 else (q - 1, -1, -1)
        running = by_bin[first, c]
        for a in range(first, last, way):
            value = by_bin[a, c]
            running = value if value > running else running
            by_bin[a, c] = running


@njit(cache=True)
def total_risk(by_bin: FloatArray, total: FloatArray) -> None:
    """``total[a]``: the probability that any criterion's failure follows bin a, its
    criteria's risks taken as independent (``1 - prod_c (1 - risk_c)``)."""
    q, n_c = by_bin.shape
    for a in range(q):
        spared = 1.0
        for c in range(n_c):
            spared *= 1.0 - min(max(by_bin[a, c], 0.0), 1.0)
        total[a] = 1.0 - spared


@njit(cache=True)
def nearest_allowed(total: FloatArray, proposed_bin: int, limit: float) -> int:
    """The bin within ``limit`` nearest to ``proposed_bin`` (the proposal itself when it is
    within it), the one of lower total risk of two equally near (the lower bin of equals)."""
    best = -1
    for a in range(total.shape[0]):
        if total[a] > limit:
            continue
        if best < 0:
            best = a
            continue
        near, best_near = abs(a - proposed_bin), abs(best - proposed_bin)
        if near < best_near or (near == best_near and total[a] < total[best]):
            best = a
    return best


@njit(cache=True)
def decide(
    by_bin: FloatArray,
    reached: FloatArray,
    use_reach: bool,
    proposed_bin: int,
    threshold: float,
    margin: float,
    verdicts: IntArray,
) -> tuple[float, int, int, bool]:
    """One decision on the local model's risks (``by_bin``, actions x criteria) and the
    reach's (``reached``, the same shape), both after
    :func:`monotone`.

    ``by_bin`` becomes the blend the decision reads (what the decision record shows): the
    mean of the two where the reach is on (``use_reach``), the local risk alone otherwise.
    ``verdicts`` gets each bin's: -1 when its total risk is within the limit, else its riskiest
    criterion (the first of equals). Returns the limit (``threshold``, or ``margin`` above the
    least total risk, whichever is higher), the proposal's verdict, the bin to apply and
    whether that is the proposal."""
    q, n_c = by_bin.shape
    if use_reach:
        for a in range(q):
            for c in range(n_c):
                by_bin[a, c] = 0.5 * (by_bin[a, c] + reached[a, c])
    total = np.empty(q)
    total_risk(by_bin, total)
    limit = max(threshold, total.min() + margin)
    for a in range(q):
        worst = 0
        for c in range(1, n_c):
            if by_bin[a, c] > by_bin[a, worst]:
                worst = c
        verdicts[a] = -1 if total[a] <= limit else worst
    final = nearest_allowed(total, proposed_bin, limit)
    return limit, verdicts[proposed_bin], final, final == proposed_bin
