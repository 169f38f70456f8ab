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
from numba import njit

from app.core._kernels import pairwise_sum

FloatArray = npt.NDArray[np.float64]
IndexArray = npt.NDArray[np.int64]


@dataclass(slots=True)
class Belief:
    """A sparse distribution over states: ascending ``index`` and matching ``prob`` (sum 1).
    Made on every step, so a plain slotted record (not frozen: that costs more to build)."""

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
    """Eq. 1 as a numerically stable softmax of ``-d_i^2 / var_i``, truncated to the top k
    (ties to the lower index)."""
    size = min(sq_distances.shape[0], k)
    index = np.empty(size, dtype=np.int64)
    prob = np.empty(size)
    m = _recognise(sq_distances, variances, k, index, prob)
    return Belief(index[:m], prob[:m])


@njit(cache=True, error_model="numpy")  # variances are positive: no check, so it vectorises
def _recognise(
    sq_distances: FloatArray, variances: FloatArray, k: int, index: IndexArray, prob: FloatArray
) -> int:
    """Fill ``index`` (ascending) and ``prob`` with the belief; return its size."""
    n = sq_distances.shape[0]
    logits = np.empty(n)
    for i in range(n):  # apart from the reduction, so that it vectorises
        logits[i] = -sq_distances[i] / variances[i]
    top = -math.inf
    for i in range(n):
        top = max(top, logits[i])
    # the k largest logits within NEGLIGIBLE_LOGIT of the top, kept sorted by (logit desc,
    # index asc) in index/prob as scratch
    m = 0
    for i in range(n):
        logit = logits[i]
        if n > k and logit < top + NEGLIGIBLE_LOGIT:
            continue
        if m == k and logit <= prob[m - 1]:
            continue
        j = m if m < k else k - 1
        while j > 0 and prob[j - 1] < logit:
            prob[j], index[j] = prob[j - 1], index[j - 1]
            j -= 1
        prob[j], index[j] = logit, i
        m = min(m + 1, k)
    index[:m].sort()
    for j in range(m):
        prob[j] = logits[index[j]]
    kept = 0
    for j in range(m):
        weight = math.exp(prob[j] - top)
        if weight > 0.0:
            index[kept], prob[kept] = index[j], weight
            kept += 1
    total = pairwise_sum(prob, kept)
    for j in range(kept):
        prob[j] /= total
    return kept
