"""The action reviser: Alg. 1 (variant threshold), Alg. 3 (inspect), Alg. 2 (search), the
k-step prediction of Eqs. 5-7 and the revision noise (docs/algorithm.md).

Verdicts are integers: ``OK`` (-1) or the index of the criterion an action is predicted to
meet, which is also its priority (0 = highest).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from typing import Literal

import numpy as np
import numpy.typing as npt

from app.core.belief import Belief, top_k
from app.core.config import ReviserConfig
from app.core.tpm import TransitionModel

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
OK = -1


def variant_threshold(pred: FloatArray) -> float:
    """Alg. 1: ``X = sort(pred, desc)``, ``E = sum_j j X(j)``, ``rho_t = X(floor(E))``.

    A peaked prediction (E < 2) gives the maximum; a diffuse one a small threshold, so that
    more states count as likely.
    """
    # ascending sort (predictions are a few sorted runs: timsort wins); X(r) = s[n - r], so
    # E = sum_r r X(r) = sum_i (n - i) s[i]
    s = np.sort(pred, kind="stable")
    n = s.size
    expected_rank = float(np.sum(_descending_ranks(n) * s))  # not BLAS: a fixed order
    index = min(max(int(math.floor(expected_rank)), 1), n)  # guard against round-off
    return float(s[n - index])


@functools.lru_cache(maxsize=4)
def _descending_ranks(n: int) -> FloatArray:
    """[n, n-1, ..., 1]: the rank in descending order of each ascending position."""
    ranks = np.arange(n, 0, -1, dtype=np.float64)
    ranks.flags.writeable = False
    return ranks


def inspect(
    pred: FloatArray,
    threshold: float,
    flagged: tuple[IntArray, IntArray],
    rule: Literal["any", "first_index"],
) -> int:
    """Alg. 3: the criterion an action is predicted to meet, or ``OK``.

    ``flagged`` holds the flagged states (ascending) and their flags. ``any``: the
    highest-priority flag among all states at or above the threshold. ``first_index``: the
    literal loop, which answers with the first such state by index.
    """
    index, flags = flagged
    if rule == "first_index":
        first = int(np.argmax(pred >= threshold))  # one exists: threshold <= max(pred)
        at = int(np.searchsorted(index, first))
        return int(flags[at]) - 1 if at < index.size and index[at] == first else OK
    likely = flags[pred[index] >= threshold]
    return int(likely.min()) - 1 if likely.size else OK


def risk(pred: FloatArray, flagged: tuple[IntArray, IntArray], n_criteria: int) -> FloatArray:
    """Predicted probability mass on the states of each criterion."""
    index, flags = flagged
    mass = np.bincount(flags, weights=pred[index], minlength=n_criteria + 1)[1:]
    return np.asarray(mass, dtype=np.float64)


def predict_ahead(
    model: TransitionModel,
    belief: Belief,
    action_bin: int,
    config: ReviserConfig,
    k: int,
) -> FloatArray:
    """Eqs. 5-7: one step under the action, then ``horizon - 1`` steps of the marginal TPM.

    ``P* = (1/q) sum_r P^r`` (Eq. 7, uniform action prior). ``iterate`` applies it
    ``horizon - 1`` times (A11); ``single`` applies it once, as Eq. 6 is written. Each
    propagated distribution is truncated to its top-k states like a belief.
    """
    pred = model.predict(belief, action_bin, config.transpose)
    extra = config.horizon - 1 if config.multi_step == "iterate" else min(config.horizon - 1, 1)
    for _ in range(extra):
        pred = model.predict_marginal(top_k(np.maximum(pred, 0.0), k), config.transpose)
    return pred


def search(
    start_bin: int,
    verdict: int,
    directions: Sequence[str | None],
    n_bins: int,
    literal: bool,
    assess: Callable[[int], int],
) -> tuple[int, list[tuple[int, int]]]:
    """Alg. 2: step through the bins away from the predicted criterion until it clears.

    A ``decrease`` criterion (collision) searches slower actions, an ``increase`` one (large
    distance) faster ones. The fixed form (A6) stops at the last bin instead of the
    literal ``r > 0`` off-by-one, and steps back when the search runs into a criterion of
    higher priority (an upward search that meets a collision). Returns the chosen bin and the
    ``(bin, verdict)`` of every candidate tried.
    """
    step = -1 if directions[verdict] == "decrease" else 1
    r, current, tried = start_bin, verdict, []
    while current == verdict:
        nxt = r + step
        if not 0 <= nxt < n_bins:
            if literal and step < 0:
                r = -1  # the literal loop reaches r = 0 (1-based), below every bin
            break
        r = nxt
        current = assess(r)
        tried.append((r, current))
        if not literal and current != OK and current < verdict:
            r -= step
            break
    return r, tried


def noise_std(config: ReviserConfig, a_max: float, episode: int) -> float:
    """Std of N(0, V) with ``V = a_max / max(1, K * episode)``, V a variance or a std
    (``noise``; docs/algorithm.md)."""
    v = a_max / max(1.0, config.noise_k * episode)
    return math.sqrt(v) if config.noise == "variance" else v
