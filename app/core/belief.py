"""Recognition, Eq. 1: the belief Prob(S_t) over states (docs/algorithm.md).

``eta_i = exp(-||z - s_i||^2 / var_i)`` and ``lambda_i = eta_i / sum_j eta_j``, computed as a
softmax of the logits so that an observation far from every state still gets a distribution
(the literal form gives 0/0 there). Beliefs are sparse: the top-k states by likelihood,
renormalised, which is exact when k is at least the number of states.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
IndexArray = npt.NDArray[np.int64]


@dataclass(frozen=True)
class Belief:
    """A sparse distribution over states: ascending ``index`` and matching ``prob`` (sum 1)."""

    index: IndexArray
    prob: FloatArray

    def argmax(self) -> int:
        """The recognised state: the most likely one, the lowest index among ties."""
        return int(self.index[int(self.prob.argmax())])

    def segments(self, n_states: int) -> IndexArray:
        """How many of the n states lie before the first belief state, between each pair of
        them (the upper one included) and after the last: the runs of columns j that share
        the same belief states i < j."""
        edges = np.empty(self.index.size + 2, dtype=np.int64)
        edges[0], edges[-1] = 0, n_states
        np.add(self.index, 1, out=edges[1:-1])
        out: IndexArray = edges[1:] - edges[:-1]
        return out

    def dense(self, n_states: int) -> FloatArray:
        """The belief as a length-n vector."""
        out = np.zeros(n_states)
        out[self.index] = self.prob
        return out


def top_k(weights: FloatArray, k: int) -> Belief:
    """The k largest entries of a non-negative vector, renormalised into a Belief."""
    n = weights.shape[0]
    if n > k:
        index = np.sort(np.argpartition(-weights, k - 1)[:k])
    else:
        index = np.arange(n)
    prob = weights[index]
    keep = prob > 0.0
    index, prob = index[keep], prob[keep]
    return Belief(index.astype(np.int64), prob / prob.sum())


# States whose weight is below machine epsilon of the largest cannot change the normalised
# belief of the others; skipping them keeps the top-k selection off the whole state set.
NEGLIGIBLE_LOGIT = math.log(np.finfo(np.float64).eps)


def recognise(sq_distances: FloatArray, variances: FloatArray, k: int) -> Belief:
    """Eq. 1 as a numerically stable softmax of ``-d_i^2 / var_i``, truncated to the top k."""
    logits = -sq_distances / variances
    if logits.shape[0] > k:
        index = np.flatnonzero(logits >= logits.max() + NEGLIGIBLE_LOGIT)
        if index.size > k:
            index = np.sort(index[np.argpartition(-logits[index], k - 1)[:k]])
    else:
        index = np.arange(logits.shape[0])
    chosen = logits[index]
    weights = np.exp(chosen - chosen.max())
    keep = weights > 0.0
    weights = weights[keep]
    return Belief(index[keep].astype(np.int64, copy=False), weights / weights.sum())
