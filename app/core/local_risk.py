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

**Monotone prior.** A criterion's direction gives the safe side (braking never raises the
risk of a collision), so the risks over the action bins are lifted to their running maximum
from the safe end (:func:`app.core.risk.monotone`). A criterion declared without a direction
has no safe side: a bin never tried in a state takes the risk of the nearest bin tried there,
and the box rule above does not apply.

**Reach.** Beside the risk, the model learns each state's dynamics and where failures were seen
(:mod:`app.core.reach`): whether a failure can still be avoided after an action under the safest
continuation, which the behaviour's confounds cannot hide. The decision asks both
(:func:`app.core.risk.decide`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import numpy.typing as npt
from numba import njit

from app.core import _stored as stored
from app.core import reach, risk
from app.core._arrays import ensure_capacity, read_only
from app.core._kernels import weighted_rls
from app.core.belief import Belief
from app.core.errors import InvalidSnapshot

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

PRIOR_COV = 100.0  # initial covariance of every weight: a ridge of 1 / 100
MIN_WEIGHT = 1e-3  # belief weights below this do not update a state


class LocalRisk:
    """The per-state linear risk models, and each stream's unlabelled steps.

    A stream is known here by its slot (a small integer the shield hands out): its steps wait
    in a ring of ``horizon + 1`` rows of arrays, each the step's belief (states, padded with
    -1 and weight 0 up to ``belief_size``) and its ``phi``."""

    def __init__(
        self,
        dim: int,
        n_criteria: int,
        n_bins: int,
        horizon: int,
        max_states: int,
        belief_size: int,
        max_streams: int,
        reach_horizon: int = 0,
        reach_radius: float = 0.05,
        bounds: FloatArray | None = None,
    ) -> None:
        self.dim, self.n_criteria, self.n_bins = dim, n_criteria, n_bins
        self.horizon, self.max_states, self.belief_size = horizon, max_states, belief_size
        self.max_streams = max_streams
        self.reach_horizon, self.reach_radius = reach_horizon, reach_radius
        # per criterion its bound in the clustering space (reach.no_bounds: none)
        self.bounds = reach.no_bounds(n_criteria) if bounds is None else bounds
        self.size = dim + 2  # [1, z, u]
        self._n = 0
        self._theta = np.zeros((0, n_criteria, self.size))
        self._cov = np.zeros((0, self.size, self.size))
        self._tried = np.zeros((0, n_bins), dtype=np.int64)  # steps per state and bin
        # per state and bin, the box of the observations it was applied at (empty: inf, -inf)
        self._low = np.zeros((0, n_bins, dim))
        self._high = np.zeros((0, n_bins, dim))
        # where the observation was seen: the union of those boxes (rows low, high; empty: the
        # low row above the high one)
        self._extent = np.array([[np.inf] * dim, [-np.inf] * dim])
        self.midpoints = (np.arange(n_bins) + 0.5) / n_bins
        ring = horizon + 1
        self._queue_index = np.zeros((0, ring, belief_size), dtype=np.int64)
        self._queue_prob = np.zeros((0, ring, belief_size))
        self._queue_phi = np.zeros((0, ring, self.size))
        self._queue_ends = np.zeros((0, 2), dtype=np.int64)  # per slot: first row, length
        self.failures = np.zeros(n_criteria, dtype=np.int64)  # learned, per criterion
        # the dynamics per state (dimension x [1, z, u]) and the failures seen (app.core.reach)
        self._dynamics = np.zeros((0, dim, self.size))
        self._dynamics_cov = np.zeros((0, self.size, self.size))
        self._peak = np.zeros(dim)  # the peak one-step error per dimension (app.core.reach)
        self._points = np.zeros((n_criteria, reach.MAX_POINTS, dim))
        self._point_counts = np.zeros((n_criteria, 2), dtype=np.int64)  # kept, next slot
        self._arrays: tuple[Any, ...] | None = None  # see arrays

    @property
    def any_failure(self) -> bool:
        """Whether a failure was learned (before one, every risk is 0)."""
        return bool(self.failures.any())

    @property
    def theta(self) -> FloatArray:
        """The weights, states x criteria x [1, z, u] (read-only view)."""
        return read_only(self._theta[: self._n])

    def add_state(self) -> None:
        """A new state: no risk and no motion until it learns otherwise, weights free to
        move."""
        n = self._n
        self._theta = ensure_capacity(self._theta, n + 1, self.max_states)
        self._cov = ensure_capacity(self._cov, n + 1, self.max_states)
        self._tried = ensure_capacity(self._tried, n + 1, self.max_states)
        self._theta[n] = 0.0
        self._cov[n] = np.eye(self.size) * PRIOR_COV
        self._dynamics = ensure_capacity(self._dynamics, n + 1, self.max_states)
        self._dynamics_cov = ensure_capacity(self._dynamics_cov, n + 1, self.max_states)
        self._dynamics[n] = 0.0
        self._dynamics_cov[n] = np.eye(self.size) * PRIOR_COV
        self._tried[n] = 0
        self._low = ensure_capacity(self._low, n + 1, self.max_states)
        self._high = ensure_capacity(self._high, n + 1, self.max_states)
        self._low[n] = np.inf
        self._high[n] = -np.inf
        self._n = n + 1
        self._arrays = None

    def reserve(self, slot: int) -> None:
        """Room for the steps of the stream in ``slot``."""
        if slot < self._queue_ends.shape[0]:
            return
        limit = self.max_streams
        self._queue_index = ensure_capacity(self._queue_index, slot + 1, limit)
        self._queue_prob = ensure_capacity(self._queue_prob, slot + 1, limit)
        self._queue_phi = ensure_capacity(self._queue_phi, slot + 1, limit)
        self._queue_ends = ensure_capacity(self._queue_ends, slot + 1, limit)
        self._arrays = None

    def learn(
        self,
        slot: int,
        belief: Belief,
        z: FloatArray,
        action_bin: int,
        failure: int | None,
        ended: bool,
    ) -> None:
        """The previous step of the stream in ``slot`` (``belief`` and ``z`` before it,
        ``action_bin`` applied) ended in ``failure`` (a criterion index) or not; ``ended``
        closes its episode. One compiled call."""
        self.reserve(slot)
        learn_step(
            self.arrays(),
            slot,
            belief.index,
            belief.prob,
            z,
            action_bin,
            -1 if failure is None else failure,
            ended,
        )

    def learn_motion(
        self,
        belief: Belief,
        before: FloatArray,
        action_bin: int,
        after: FloatArray,
        failure: int | None,
    ) -> None:
        """A step of the reach (:mod:`app.core.reach`): the dynamics of the belief's states
        from ``before`` under ``action_bin`` to ``after``, and ``after`` kept as a failure
        point of criterion ``failure``, if one. What a shield's step learns in its compiled
        call, for a model built by hand."""
        phi = np.array([1.0, *before, self.midpoints[action_bin]])
        reach.learn(
            self._dynamics, self._dynamics_cov, self._peak, belief.index, belief.prob, phi, after
        )
        if failure is not None:
            reach.add_failure(self._points, self._point_counts, failure, after, self.reach_radius)

    def arrays(self) -> tuple[Any, ...]:
        """What a compiled step learns and decides with, one tuple in :func:`learn_step`'s
        order: the horizon, the weights and their covariances, the steps and boxes per state
        and bin, the extent, the midpoints, the streams' queues, the failures learned, then the
        reach's tuple (:func:`app.core.reach.risk`: its horizon and radius, the dynamics,
        their covariances, the peak one-step error, the failure points, their counts and the
        bounds). The same tuple until a state is added or a new slot reserved."""
        if self._arrays is None:
            self._arrays = (
                self.horizon,
                self._theta,
                self._cov,
                self._tried,
                self._low,
                self._high,
                self._extent,
                self.midpoints,
                self._queue_index,
                self._queue_prob,
                self._queue_phi,
                self._queue_ends,
                self.failures,
                (
                    self.reach_horizon,
                    self.reach_radius,
                    self._dynamics,
                    self._dynamics_cov,
                    self._peak,
                    self._points,
                    self._point_counts,
                    self.bounds,
                ),
            )
        return self._arrays

    def pending(self, slot: int) -> int:
        """How many steps of the stream in ``slot`` await their labels."""
        return int(self._queue_ends[slot, 1]) if slot < self._queue_ends.shape[0] else 0

    def forget(self, slot: int) -> None:
        """Drop the unlabelled steps in ``slot`` (a stream that expired or ended)."""
        if slot < self._queue_ends.shape[0]:
            self._queue_ends[slot] = 0

    def failure_points(self, criterion: int) -> FloatArray:
        """The observations (clustering space) where the reach keeps ``criterion``'s
        failures, oldest slot first (read-only)."""
        return read_only(self._points[criterion, : self._point_counts[criterion, 0]])

    @property
    def tried(self) -> IntArray:
        """Steps learned per state (the belief's most likely) and action bin (read-only)."""
        return read_only(self._tried[: self._n])

    def read(self, belief: Belief, z: FloatArray, safe: IntArray, out: FloatArray) -> None:
        """``out`` (bins x criteria): each action's risk at ``z`` under ``belief``, untried
        bins as their nearest tried bin on the safe side (``safe`` per criterion from
        :func:`app.core.risk.safe_steps`), none for the bins safer than every bin applied
        near ``z``, before the monotone prior."""
        _read(
            self._theta,
            self._tried,
            self._low,
            self._high,
            belief.index,
            belief.prob,
            z,
            self.midpoints,
            safe,
            out,
        )

    def decide(
        self,
        belief: Belief,
        z: FloatArray,
        proposed_bin: int,
        threshold: float,
        margin: float,
        safe: IntArray,
        by_bin: FloatArray,
        verdicts: IntArray,
    ) -> tuple[float, int, int, bool]:
        """The risk reviser's decision on a proposal at ``z``
        (:func:`app.core.risk.decide`): ``by_bin`` gets each action's risk per criterion, the
        blend of the local model's (:meth:`read`) and the reach's, each under the monotone
        prior, and ``verdicts`` each bin's verdict; one compiled call."""
        return decide_step(
            self.arrays(),
            belief.index,
            belief.prob,
            z,
            safe,
            proposed_bin,
            threshold,
            margin,
            by_bin,
            verdicts,
        )

    def snapshot(self, slots: Mapping[str, int]) -> dict[str, Any]:
        """Exact state as arrays: the weights, their covariances, the bins' boxes, the
        dynamics and the failure points, and the pending steps of the streams named in
        ``slots`` (name to slot), in its order."""
        names, lengths, sizes, index, prob, phi = [], [], [], [], [], []
        ring = self.horizon + 1
        for name, slot in slots.items():
            length = self.pending(slot)
            if not length:
                continue
            names.append(name)
            lengths.append(length)
            first = int(self._queue_ends[slot, 0])
            for row in ((first + j) % ring for j in range(length)):
                size = int((self._queue_index[slot, row] >= 0).sum())
                sizes.append(size)
                index.append(self._queue_index[slot, row, :size])
                prob.append(self._queue_prob[slot, row, :size])
                phi.append(self._queue_phi[slot, row])
        return {
            "theta": self.theta.copy(),
            "cov": self._cov[: self._n].copy(),
            "tried": self.tried.copy(),
            **self._boxes(),
            "failures": self.failures.copy(),
            "dynamics": self._dynamics[: self._n].copy(),
            "dynamics_cov": self._dynamics_cov[: self._n].copy(),
            "peak": self._peak.copy(),
            "points": self._points.copy(),
            "point_counts": self._point_counts.copy(),
            "streams": names,
            "lengths": np.array(lengths, dtype=np.int64),
            "sizes": np.array(sizes, dtype=np.int64),
            "index": np.concatenate(index) if index else np.zeros(0, dtype=np.int64),
            "prob": np.concatenate(prob) if prob else np.zeros(0),
            "phi": np.array(phi).reshape(-1, self.size),
        }

    def _boxes(self) -> dict[str, FloatArray]:
        """The boxes, finite: an empty one (never applied) as low 1, high 0."""
        low, high = self._low[: self._n], self._high[: self._n]
        empty = low > high
        return {"low": np.where(empty, 1.0, low), "high": np.where(empty, 0.0, high)}

    @classmethod
    def restore(
        cls, shape: LocalRisk, n_states: int, slots: Mapping[str, int], data: dict[str, Any]
    ) -> LocalRisk:
        """Rebuild from :meth:`snapshot` output into a model of ``shape``'s sizes (an empty
        one), checking every part; ``slots`` gives each stream of the model its slot."""
        self = cls(
            shape.dim,
            shape.n_criteria,
            shape.n_bins,
            shape.horizon,
            shape.max_states,
            shape.belief_size,
            shape.max_streams,
            shape.reach_horizon,
            shape.reach_radius,
            shape.bounds,
        )
        dim, n_criteria, n_bins, m = self.dim, self.n_criteria, self.n_bins, self.size
        theta = stored.floats(data["theta"], "local_risk.theta", (n_states, n_criteria, m))
        # the covariance only shrinks from PRIOR_COV * I as steps are fitted
        cov = stored.floats(
            data["cov"], "local_risk.cov", (n_states, m, m), low=-PRIOR_COV, high=PRIOR_COV
        )
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
                raise InvalidSnapshot(
                    "a box whose low end lies above its high end in some "
                    "dimensions only (empty boxes: in all)",
                    field="local_risk.low",
                )
            self._low[~empty], self._high[~empty] = low[~empty], high[~empty]
            if (~empty).any():
                self._extent[0] = low[~empty].min(axis=0)
                self._extent[1] = high[~empty].max(axis=0)
        self.failures = stored.ints(data["failures"], "local_risk.failures", (n_criteria,)).copy()
        self._restore_reach(n_states, data)
        self._restore_pending(n_states, slots, data)
        return self

    def _restore_reach(self, n_states: int, data: dict[str, Any]) -> None:
        """The dynamics, the peak one-step error and the failure points (a snapshot from
        before them: none learned; one from before the peak, whose states kept a spread each,
        the peak still to learn)."""
        m, shape = self.size, (n_states, self.dim, self.size)
        self._dynamics = np.zeros(shape)
        self._dynamics_cov = np.zeros((n_states, m, m))
        self._dynamics_cov[:] = np.eye(m) * PRIOR_COV
        self._peak = np.zeros(self.dim)
        if "peak" in data:
            self._peak = stored.floats(data["peak"], "local_risk.peak", (self.dim,), low=0.0).copy()
        if "dynamics" not in data:
            return
        self._dynamics = stored.floats(data["dynamics"], "local_risk.dynamics", shape).copy()
        self._dynamics_cov = stored.floats(
            data["dynamics_cov"],
            "local_risk.dynamics_cov",
            (n_states, m, m),
            low=-PRIOR_COV,
            high=PRIOR_COV,
        ).copy()
        self._points = stored.floats(data["points"], "local_risk.points", self._points.shape).copy()
        limit = reach.MAX_POINTS
        counts = stored.ints(
            data["point_counts"], "local_risk.point_counts", (self.n_criteria, 2), low=0, high=limit
        )
        kept, slot = counts[:, 0], counts[:, 1]
        if (slot >= limit).any() or ((kept < limit) & (slot != kept)).any():
            raise InvalidSnapshot(
                "a failure point's next slot lies beyond those kept",
                field="local_risk.point_counts",
            )
        self._point_counts = counts.copy()

    def _restore_pending(
        self, n_states: int, slots: Mapping[str, int], data: dict[str, Any]
    ) -> None:
        if slots:
            self.reserve(max(slots.values()))
        names = data["streams"]
        if not isinstance(names, list) or not all(isinstance(s, str) for s in names):
            raise InvalidSnapshot("pending streams must be names", field="local_risk.streams")
        if len(set(names)) != len(names) or not set(names) <= set(slots):
            raise InvalidSnapshot(
                "pending steps name each of the model's streams at most once",
                field="local_risk.streams",
            )
        lengths = stored.ints(
            data["lengths"], "local_risk.lengths", (len(names),), low=1, high=self.horizon + 1
        )
        steps = int(lengths.sum())
        sizes = stored.ints(
            data["sizes"], "local_risk.sizes", (steps,), low=1, high=self.belief_size
        )
        index = stored.ints(
            data["index"], "local_risk.index", (int(sizes.sum()),), low=0, high=max(n_states - 1, 0)
        )
        prob = stored.floats(data["prob"], "local_risk.prob", index.shape, low=0.0, high=1.0)
        phi = stored.floats(data["phi"], "local_risk.phi", (steps, self.size))
        at = row = 0
        for name, length in zip(names, lengths.tolist(), strict=True):
            slot = slots[name]  # (reserved above, with the highest)
            self._queue_ends[slot] = (0, length)
            for j in range(length):
                size = int(sizes[row])
                self._queue_index[slot, j] = -1
                self._queue_index[slot, j, :size] = index[at : at + size]
                self._queue_prob[slot, j] = 0.0
                self._queue_prob[slot, j, :size] = prob[at : at + size]
                self._queue_phi[slot, j] = phi[row]
                at, row = at + size, row + 1


@njit(cache=True)
def learn_step(
    model: Any,
    slot: int,
    index: IntArray,
    prob: FloatArray,
    z: FloatArray,
    action_bin: int,
    failure: int,
    ended: bool,
) -> None:
    """:meth:`LocalRisk.learn` on ``model`` (:meth:`LocalRisk.arrays`; ``failure`` -1: none):
    count the step in the belief's most likely state (the lowest index of equals) and widen
    that bin's box there to hold ``z``, queue it with its ``phi(z, u) = [1, z, u]``, then fit
    the steps whose labels are known: the oldest once it is ``horizon`` steps old, or every
    queued one at a failure or the episode's end."""
    (
        horizon,
        theta,
        cov,
        tried,
        low,
        high,
        extent,
        midpoints,
        queue_index,
        queue_prob,
        queue_phi,
        queue_ends,
        failures,
        _,
    ) = model
    home = index[np.argmax(prob)]
    tried[home, action_bin] += 1
    ring, d = queue_phi.shape[1], z.shape[0]
    first, length = queue_ends[slot, 0], queue_ends[slot, 1]
    row = (first + length) % ring
    queue_index[slot, row, :] = -1
    queue_prob[slot, row, :] = 0.0
    for t in range(index.shape[0]):
        queue_index[slot, row, t] = index[t]
        queue_prob[slot, row, t] = prob[t]
    phi = queue_phi[slot, row]
    phi[0] = 1.0
    for r in range(d):
        low[home, action_bin, r] = min(low[home, action_bin, r], z[r])
        high[home, action_bin, r] = max(high[home, action_bin, r], z[r])
        extent[0, r] = min(extent[0, r], z[r])
        extent[1, r] = max(extent[1, r], z[r])
        phi[r + 1] = z[r]
    phi[d + 1] = midpoints[action_bin]
    length += 1
    labels = np.zeros(failures.shape[0])
    if failure < 0 and not ended:
        if length > horizon:  # old enough: no failure followed within it
            _fit(
                theta,
                cov,
                queue_index[slot, first],
                queue_prob[slot, first],
                queue_phi[slot, first],
                labels,
            )
            first, length = (first + 1) % ring, length - 1
        queue_ends[slot, 0], queue_ends[slot, 1] = first, length
        return
    if failure >= 0:
        labels[failure] = 1.0
        failures[failure] += 1
    for j in range(length):
        row = (first + j) % ring
        _fit(
            theta, cov, queue_index[slot, row], queue_prob[slot, row], queue_phi[slot, row], labels
        )
    queue_ends[slot, 0], queue_ends[slot, 1] = 0, 0


@njit(cache=True)
def learn_outcome(
    model: Any,
    slot: int,
    prev_index: IntArray,
    prev_prob: FloatArray,
    prev_z: FloatArray,
    action_bin: int,
    failure: int,
    ended: bool,
    z: FloatArray,
) -> bool:
    """What a shield's step teaches ``model`` (:meth:`LocalRisk.arrays`): the stream's previous
    step (``prev_*``, ``action_bin`` applied; -1: none to learn) into the risk labels
    (:func:`learn_step`) and, with the reach, its move to ``z`` into the dynamics; ``z`` kept
    as a failure point of ``failure`` (-1: none). Returns whether any failure was learned."""
    failures, motion = model[12], model[13]
    reach_horizon = motion[0]
    if action_bin >= 0:
        learn_step(model, slot, prev_index, prev_prob, prev_z, action_bin, failure, ended)
        if reach_horizon > 0:
            phi = np.empty(prev_z.shape[0] + 2)
            phi[0], phi[1:-1], phi[-1] = 1.0, prev_z, model[7][action_bin]
            reach.learn(motion[2], motion[3], motion[4], prev_index, prev_prob, phi, z)
    if failure >= 0 and reach_horizon > 0:
        reach.add_failure(motion[5], motion[6], failure, z, motion[1])
    return bool(failures.any())


@njit(cache=True)
def _fit(
    theta: FloatArray,
    cov: FloatArray,
    index: IntArray,
    prob: FloatArray,
    phi: FloatArray,
    labels: FloatArray,
) -> None:
    """One labelled step into each belief state's weights: weighted recursive least squares
    with weight ``prob`` (the state's membership), every criterion sharing the covariance.
    Entries of weight below ``MIN_WEIGHT`` (the queue's padding among them) change nothing."""
    weighted_rls(theta, cov, index, prob, phi, labels, MIN_WEIGHT)


@njit(cache=True)
def _near(low: FloatArray, high: FloatArray, i: int, a: int, z: FloatArray) -> bool:
    """Whether ``z`` lies in the box where state ``i`` saw bin ``a`` applied."""
    for r in range(z.shape[0]):
        if z[r] < low[i, a, r] or z[r] > high[i, a, r]:
            return False
    return True


@njit(cache=True)
def _read(
    theta: FloatArray,
    tried: IntArray,
    low: FloatArray,
    high: FloatArray,
    index: IntArray,
    prob: FloatArray,
    z: FloatArray,
    midpoints: FloatArray,
    safe: IntArray,
    out: FloatArray,
) -> None:
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
            if safe[c] == 0:
                _read_undirected(theta, tried, i, c, base, midpoints, prob[t], out)
                continue
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
def _read_undirected(
    theta: FloatArray,
    tried: IntArray,
    i: int,
    c: int,
    base: float,
    midpoints: FloatArray,
    weight: float,
    out: FloatArray,
) -> None:
    """A criterion without a direction in state ``i``: its model on the bins tried there, the
    nearest tried bin's risk on the others (the riskier of two equally near), none where no
    bin was tried; added to ``out`` with ``weight``."""
    q, d = midpoints.shape[0], theta.shape[2] - 2
    for a in range(q):
        best, value = q, 0.0
        for b in range(q):
            if tried[i, b] == 0 or abs(b - a) > best:
                continue
            risk_b = min(max(base + theta[i, c, d + 1] * midpoints[b], 0.0), 1.0)
            if abs(b - a) < best or risk_b > value:
                best, value = abs(b - a), risk_b
        out[a, c] += weight * value


@njit(cache=True)
def decide_step(
    model: Any,
    index: IntArray,
    prob: FloatArray,
    z: FloatArray,
    safe: IntArray,
    proposed_bin: int,
    threshold: float,
    margin: float,
    by_bin: FloatArray,
    verdicts: IntArray,
) -> tuple[float, int, int, bool]:
    """:meth:`LocalRisk.decide` on ``model`` (:meth:`LocalRisk.arrays`): :func:`_read` and the
    reach (:func:`app.core.reach.risk`), each under the monotone prior, and the decision on
    both (:func:`app.core.risk.decide`)."""
    _, theta, _, tried, low, high, extent, midpoints, _, _, _, _, _, motion = model
    _read(theta, tried, low, high, index, prob, z, midpoints, safe, by_bin)
    risk.monotone(by_bin, safe)
    reached = np.zeros(by_bin.shape)
    reach_horizon = motion[0]
    if reach_horizon > 0:
        reach.risk(motion, extent, midpoints, index, prob, z, safe, reached)
        risk.monotone(reached, safe)
    return risk.decide(
        by_bin, reached, reach_horizon > 0, proposed_bin, threshold, margin, verdicts
    )
