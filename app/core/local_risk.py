"""Risk per action, local in the observation: the risk reviser's model (``reviser.method: risk``).

For each state i and criterion c a linear model ``theta_ic . phi(z, u)`` of the probability that
a failure of c follows within ``horizon`` steps, where ``phi = [1, z, u]``: the observation in
the clustering space and the action, its bin's midpoint scaled to [0, 1]. Together the states'
models make a Takagi-Sugeno model, each weighted by the state's membership (Eq. 1's belief):

    risk_c(z, a) = clip(sum_i b_i(z) theta_ic . phi(z, u_a), 0, 1)

so the risk changes *within* a state with where the observation lies in it and with the action,
and a few broad states are enough: a crash counted under full braking at one edge of a state no
longer makes every action there as risky (the confound of counting per state and action), and a
car standing far back does not inherit the risk of close following.

**Learning.** Each applied step ``(z, a)`` waits in its stream's queue until its label is
known: 1 for criterion c when a failure of c follows within ``horizon`` steps, 0 once the step
is ``horizon`` steps old or its episode has ended without a failure. Each state's weights are
then fitted by weighted recursive least squares (the weight the step's belief gave the state),
which is exact least squares on the labelled steps, with a weak ridge prior ``1 / prior_cov``.
The label is the outcome under the behaviour that followed (controller and shield); a
revised step is learned for the action applied, never for the proposal.

**Actions not yet tried.** A linear model extrapolates in the action, and from a controller
that brakes only when it is too late it learns that braking goes with crashing. So a state's
model answers only for the bins applied in that state; a bin never tried there takes the risk
of the nearest tried bin on its safe side for that criterion, or none when no bin on its safe
side was tried: the shield may choose it, and then learns what it does. The same holds near
the observation: each state keeps, per bin, the box of observations where the bin was applied,
and the bins safer than every bin applied near ``z`` (whose box holds ``z``) carry no risk
there, whatever was learned of them elsewhere in the state. Where a controller acts only in
one way at a place, the shield tries the safer ways there; a confound learned at the state's
other end (firing the engine goes with crashing, because it is fired too late) does not hold
it back.

**Monotone prior.** Each criterion's direction gives the safe side (braking never raises the
risk of a collision), so the risks over the action bins are lifted to their running maximum
from the safe end (:func:`app.core.risk.monotone`).
"""

from __future__ import annotations

from collections import deque
from typing import Any

import numpy as np
import numpy.typing as npt
from numba import njit

from app.core import _stored as stored
from app.core import risk
from app.core._arrays import ensure_capacity, read_only
from app.core.belief import Belief
from app.core.errors import InvalidSnapshot

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

PRIOR_COV = 100.0  # initial covariance of every weight: a ridge of 1 / 100
MIN_WEIGHT = 1e-3  # belief weights below this do not update a state


Step = tuple[IntArray, FloatArray, FloatArray]  # belief states, their weights, phi(z, u)


class LocalRisk:
    """The per-state linear risk models and the streams' unlabelled steps."""

    def __init__(self, dim: int, n_criteria: int, n_bins: int, horizon: int,
                 max_states: int) -> None:
        self.dim, self.n_criteria, self.n_bins = dim, n_criteria, n_bins
        self.horizon, self.max_states = horizon, max_states
        self.size = dim + 2  # [1, z, u]
        self._n = 0
        self._theta = np.zeros((0, n_criteria, self.size))
        self._cov = np.zeros((0, self.size, self.size))
        self._tried = np.zeros((0, n_bins), dtype=np.int64)  # steps per state and bin
        # per state and bin, the box of the observations it was applied at (empty: inf, -inf)
        self._low = np.zeros((0, n_bins, dim))
        self._high = np.zeros((0, n_bins, dim))
        self.midpoints = (np.arange(n_bins) + 0.5) / n_bins
        self.pending: dict[str, deque[Step]] = {}  # per stream, the steps awaiting labels
        self.failures = np.zeros(n_criteria, dtype=np.int64)  # learned, per criterion
        self.any_failure = False  # (read every step: cheaper than asking the array)
        self._safe = np.zeros(n_criteria)  # the labels of a step no failure followed

    @property
    def theta(self) -> FloatArray:
        """The weights, states x criteria x [1, z, u] (read-only view)."""
        return read_only(self._theta[: self._n])

    def add_state(self) -> None:
        """A new state: no risk until it learns otherwise, weights free to move."""
        n = self._n
        self._theta = ensure_capacity(self._theta, n + 1, self.max_states)
        self._cov = ensure_capacity(self._cov, n + 1, self.max_states)
        self._tried = ensure_capacity(self._tried, n + 1, self.max_states)
        self._theta[n] = 0.0
        self._cov[n] = np.eye(self.size) * PRIOR_COV
        self._tried[n] = 0
        self._low = ensure_capacity(self._low, n + 1, self.max_states)
        self._high = ensure_capacity(self._high, n + 1, self.max_states)
        self._low[n] = np.inf
        self._high[n] = -np.inf
        self._n = n + 1

    def learn(self, stream: str, belief: Belief, z: FloatArray, action_bin: int,
              failure: int | None, ended: bool) -> None:
        """The stream's previous step (``belief`` and ``z`` before it, ``action_bin`` applied)
        ended in ``failure`` (a criterion index) or not; ``ended`` closes its episode."""
        queue = self.pending.setdefault(stream, deque())
        phi = _observe(self._tried, self._low, self._high, belief.index, belief.prob, z,
                       action_bin, self.midpoints)
        # a step's belief arrays are its own and never written after (no copy needed)
        queue.append((belief.index, belief.prob, phi))
        if failure is None and not ended:
            if len(queue) > self.horizon:  # old enough: no failure followed within it
                _fit(self._theta, self._cov, *queue.popleft(), self._safe)
            return
        labels = self._safe
        if failure is not None:
            labels = np.zeros(self.n_criteria)
            labels[failure] = 1.0
            self.failures[failure] += 1
            self.any_failure = True
        for step in queue:
            _fit(self._theta, self._cov, *step, labels)
        del self.pending[stream]

    def forget(self, stream: str) -> None:
        """Drop a stream's unlabelled steps (a stream that expired)."""
        self.pending.pop(stream, None)

    @property
    def tried(self) -> IntArray:
        """Steps learned per state (the belief's most likely) and action bin (read-only)."""
        return read_only(self._tried[: self._n])

    def read(self, belief: Belief, z: FloatArray, safe: IntArray, out: FloatArray) -> None:
        """``out`` (bins x criteria): each action's risk at ``z`` under ``belief``, untried
        bins as their nearest tried bin on the safe side (``safe`` per criterion from
        :func:`app.core.risk.safe_steps`), none for the bins safer than every bin applied
        near ``z``, before the monotone prior."""
        _read(self._theta, self._tried, self._low, self._high, belief.index, belief.prob, z,
              self.midpoints, safe, out)

    def decide(self, belief: Belief, z: FloatArray, proposed_bin: int, threshold: float,
               margin: float, safe: IntArray, by_bin: FloatArray, verdicts: IntArray
               ) -> tuple[float, int, int, bool]:
        """The risk reviser's decision on a proposal at ``z`` (:func:`app.core.risk.decide`):
        ``by_bin`` gets each action's risk (:meth:`read`, then the monotone prior) and
        ``verdicts`` each bin's verdict; one compiled call."""
        return _decide(self._theta, self._tried, self._low, self._high, belief.index,
                       belief.prob, z, self.midpoints, safe, proposed_bin, threshold, margin,
                       by_bin, verdicts)

    def snapshot(self) -> dict[str, Any]:
        """Exact state as arrays: the weights, their covariances, the bins' boxes and the
        pending steps."""
        names, lengths, index, prob, phi = [], [], [], [], []
        for name, queue in self.pending.items():
            names.append(name)
            lengths.append(len(queue))
            for i, p, f in queue:
                index.append(i)
                prob.append(p)
                phi.append(f)
        sizes = [i.size for i in index]
        return {"theta": self.theta.copy(), "cov": self._cov[: self._n].copy(),
                "tried": self.tried.copy(), **self._boxes(),
                "failures": self.failures.copy(), "streams": names,
                "lengths": np.array(lengths, dtype=np.int64),
                "sizes": np.array(sizes, dtype=np.int64),
                "index": np.concatenate(index) if index else np.zeros(0, dtype=np.int64),
                "prob": np.concatenate(prob) if prob else np.zeros(0),
                "phi": np.array(phi).reshape(-1, self.size)}

    def _boxes(self) -> dict[str, FloatArray]:
        """The boxes, finite: an empty one (never applied) as low 1, high 0."""
        low, high = self._low[: self._n], self._high[: self._n]
        empty = low > high
        return {"low": np.where(empty, 1.0, low), "high": np.where(empty, 0.0, high)}

    @classmethod
    def restore(cls, dim: int, n_criteria: int, n_bins: int, horizon: int, max_states: int,
                n_states: int, data: dict[str, Any]) -> LocalRisk:
        """Rebuild from :meth:`snapshot` output, checking every part against the model."""
        self = cls(dim, n_criteria, n_bins, horizon, max_states)
        m = self.size
        theta = stored.floats(data["theta"], "local_risk.theta", (n_states, n_criteria, m))
        # the covariance only shrinks from PRIOR_COV * I as steps are fitted
        cov = stored.floats(data["cov"], "local_risk.cov", (n_states, m, m), low=-PRIOR_COV,
                            high=PRIOR_COV)
        tried = stored.ints(data["tried"], "local_risk.tried", (n_states, n_bins), low=0)
        self._theta, self._cov, self._n = theta.copy(), cov.copy(), n_states
        self._tried = tried.copy()
        self._low = np.full(tried.shape + (dim,), np.inf)
        self._high = np.full(tried.shape + (dim,), -np.inf)
        if "low" in data or "high" in data:  # (a snapshot from before them: empty boxes)
            low = stored.floats(data.get("low"), "local_risk.low", self._low.shape)
            high = stored.floats(data.get("high"), "local_risk.high", self._low.shape)
            empty = (low > high).all(axis=-1)
            if ((low > high).any(axis=-1) & ~empty).any():
                raise InvalidSnapshot("a box whose low end lies above its high end in some "
                                      "dimensions only (empty boxes: in all)",
                                      field="local_risk.low")
            self._low[~empty], self._high[~empty] = low[~empty], high[~empty]
        self.failures = stored.ints(data["failures"], "local_risk.failures", (n_criteria,)).copy()
        self.any_failure = bool(self.failures.any())
        names = data["streams"]
        if not isinstance(names, list) or not all(isinstance(s, str) for s in names):
            raise InvalidSnapshot("pending streams must be names", field="local_risk.streams")
        lengths = stored.ints(data["lengths"], "local_risk.lengths", (len(names),), low=1,
                              high=horizon + 1)
        steps = int(lengths.sum())
        sizes = stored.ints(data["sizes"], "local_risk.sizes", (steps,), low=1)
        index = stored.ints(data["index"], "local_risk.index", (int(sizes.sum()),), low=0,
                            high=max(n_states - 1, 0))
        prob = stored.floats(data["prob"], "local_risk.prob", index.shape, low=0.0, high=1.0)
        phi = stored.floats(data["phi"], "local_risk.phi", (steps, m))
        at = row = 0
        for name, length in zip(names, lengths.tolist(), strict=True):
            queue = self.pending.setdefault(name, deque())
            for _ in range(length):
                size = int(sizes[row])
                queue.append((index[at:at + size].copy(), prob[at:at + size].copy(),
                              phi[row].copy()))
                at, row = at + size, row + 1
        return self


@njit(cache=True)
def _observe(tried: IntArray, low: FloatArray, high: FloatArray, index: IntArray,
             prob: FloatArray, z: FloatArray, action_bin: int, midpoints: FloatArray
             ) -> FloatArray:
    """A step applied ``action_bin`` at ``z``: count it in the belief's most likely state (the
    lowest index of equals) and widen that bin's box there to hold ``z``; returns the step's
    ``phi(z, u) = [1, z, u]``."""
    home = index[np.argmax(prob)]
    tried[home, action_bin] += 1
    d = z.shape[0]
    phi = np.empty(d + 2)
    phi[0] = 1.0
    for r in range(d):
        low[home, action_bin, r] = min(low[home, action_bin, r], z[r])
        high[home, action_bin, r] = max(high[home, action_bin, r], z[r])
        phi[r + 1] = z[r]
    phi[d + 1] = midpoints[action_bin]
    return phi


@njit(cache=True)
def _fit(theta: FloatArray, cov: FloatArray, index: IntArray, prob: FloatArray,
         phi: FloatArray, labels: FloatArray) -> None:
    """One labelled step into each belief state's weights: weighted recursive least squares
    with weight ``prob`` (the state's membership), every criterion sharing the covariance."""
    m = phi.shape[0]
    gain = np.empty(m)
    for t in range(index.shape[0]):
        i, weight = index[t], prob[t]
        if weight < MIN_WEIGHT:
            continue
        denominator = 1.0 / weight
        for r in range(m):
            total = 0.0
            for s in range(m):
                total += cov[i, r, s] * phi[s]
            gain[r] = total
            denominator += phi[r] * total
        for c in range(labels.shape[0]):
            error = labels[c]
            for r in range(m):
                error -= theta[i, c, r] * phi[r]
            for r in range(m):
                theta[i, c, r] += gain[r] * error / denominator
        for r in range(m):
            for s in range(m):
                cov[i, r, s] -= gain[r] * gain[s] / denominator


@njit(cache=True)
def _near(low: FloatArray, high: FloatArray, i: int, a: int, z: FloatArray) -> bool:
    """Whether ``z`` lies in the box where state ``i`` saw bin ``a`` applied."""
    for r in range(z.shape[0]):
        if z[r] < low[i, a, r] or z[r] > high[i, a, r]:
            return False
    return True


@njit(cache=True)
def _read(theta: FloatArray, tried: IntArray, low: FloatArray, high: FloatArray,
          index: IntArray, prob: FloatArray, z: FloatArray, midpoints: FloatArray,
          safe: IntArray, out: FloatArray) -> None:
    """Each action's risk per criterion under the belief, clipped to [0, 1]: per belief state,
    none on the bins safer than every bin applied near ``z``, then its model on the bins
    tried in the state and the nearest tried bin on the safe side (or none) on the others."""
    d, q = z.shape[0], midpoints.shape[0]
    out[:] = 0.0
    for t in range(index.shape[0]):
        i = index[t]
        lowest, highest = q, -1  # the bins applied near z, from each end (none: q, -1)
        for a in range(q):
            if _near(low, high, i, a, z):
                lowest, highest = min(lowest, a), a
        for c in range(theta.shape[1]):
            base = theta[i, c, 0]
            for r in range(d):
                base += theta[i, c, r + 1] * z[r]
            first, last, way = (0, q, 1) if safe[c] < 0 else (q - 1, -1, -1)
            # the safest bin applied near z: before it, nothing counts (none applied: all do)
            safest = first if highest < 0 else (lowest if safe[c] < 0 else highest)
            carried = 0.0
            for a in range(first, last, way):
                if (a - safest) * way >= 0 and tried[i, a] > 0:
                    value = base + theta[i, c, d + 1] * midpoints[a]
                    carried = min(max(value, 0.0), 1.0)
                out[a, c] += prob[t] * carried


@njit(cache=True)
def _decide(theta: FloatArray, tried: IntArray, low: FloatArray, high: FloatArray,
            index: IntArray, prob: FloatArray, z: FloatArray, midpoints: FloatArray,
            safe: IntArray, proposed_bin: int, threshold: float, margin: float,
            by_bin: FloatArray, verdicts: IntArray) -> tuple[float, int, int, bool]:
    """:meth:`LocalRisk.decide`: :func:`_read`, the monotone prior and the decision."""
    _read(theta, tried, low, high, index, prob, z, midpoints, safe, by_bin)
    risk.monotone(by_bin, safe)
    return risk.decide(by_bin, proposed_bin, threshold, margin, safe, verdicts)
