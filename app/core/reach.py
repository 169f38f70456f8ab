"""Risk by reachability: where an action leads under the safest continuation, on learned dynamics.

The local risk model (:mod:`app.core.local_risk`) learns what followed an action under the
behaviour that followed it. Where a controller acts one way only at one place (it brakes, but
always too late) that behaviour is a confound: braking is learned to go with crashing, and every
action reads the same risk. This module answers the other question the issue's probabilistic
shields ask: *can* a failure still be avoided after this action, if the safest action is taken
from then on?

**Dynamics.** Each state i keeps a linear model of the change of the observation over one step,
``z' - z = W_i phi(z, u)`` with ``phi = [1, z, u]`` (the clustering space and the applied
action's bin midpoint scaled to [0, 1], as in the local risk model), fitted by weighted
recursive least squares with the weight the step's belief gave the state. Together the states'
models make a Takagi-Sugeno model of the dynamics, as the local risk model is one of the risk.
A step's change of observation follows from the action applied, whatever chose it, so the
dynamics carry no confound of the controller's choices.

**Failures.** Each criterion keeps up to :data:`MAX_POINTS` observations where its failures were
reported (a new one within half the radius of a kept one adds nothing).

**Bounds.** A criterion may declare where its failures lie (a :class:`~app.core.config.Bound`:
one observation at or below a value, or at or above one). The path's worst case is a box, one
interval a dimension, carried through the blended dynamics by interval arithmetic: each step
widens every dimension but the bound's own by its *peak*, the largest one-step error of
learned dynamics seen on it (a state's dynamics count once its intercept's variance is below
:data:`SETTLED`; the peak fades at :data:`PEAK_DECAY` a step), and keeps it within where the
observation was seen (the *extent*). So the worst case is what the world was seen to do, such
as a lead braking at its hardest, and no more: a speed never seen below zero does not go below
it, and the box stops growing where the world stops. The bound's own dimension (a distance, a
rate) is carried by the others, not disturbed: its one-step errors are the model's misfit, not
the world's doing. An action's box reaches the bound at ``tau`` steps (interpolated within
its step; ``horizon + 1`` when it does not), and its risk is how much sooner that comes than
the latest crossing of any action, ``(max tau - tau) / (horizon + 1)``: a bound tells the
actions apart, sooner against later, and adds no risk that every action shares. A worst case
is not a probability, and the risk it shares across all actions would otherwise outweigh
what the outcomes learned (declaring a bound must never make the shield prefer an action
whose learned outcomes fail).

**Reach.** For an action bin a and criterion c the belief's models are blended into one at the
current observation and rolled out for ``horizon`` steps: the first step under a, every later
one under c's safest bin (its safe end of the action range; the range's middle for a criterion
declared without a direction). The risk is the largest closeness
of the path to c's failures, ``max_t max(0, 1 - distance(z_t, failures_c) / radius)``: 1 on a
path through a seen failure, 0 on one that stays ``radius`` away from all of them. The rolled-out
model is affine, so every bin's path is ``p_t + q_t u_a`` from one rollout per criterion.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt
from numba import njit

from app.core._kernels import weighted_rls

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

MAX_POINTS = 64  # failure observations kept per criterion
MIN_WEIGHT = 1e-3  # belief weights below this do not update a state's dynamics
SETTLED = 0.01  # a state's dynamics count as learned once its intercept's variance is below
PEAK_DECAY = 1e-4  # the rate at which the peak one-step error fades, a learned step


def no_bounds(n_criteria: int) -> FloatArray:
    """The bounds of criteria that declare none, in :func:`risk`'s layout: per criterion the
    bound's dimension (-1: none), the value at or below which it fails and the value at or
    above which it fails (clustering space)."""
    bounds = np.empty((n_criteria, 3))
    bounds[:, 0], bounds[:, 1], bounds[:, 2] = -1.0, -math.inf, math.inf
    return bounds


@njit(cache=True)
def learn(
    dynamics: FloatArray,
    cov: FloatArray,
    peak: FloatArray,
    index: IntArray,
    prob: FloatArray,
    phi: FloatArray,
    z: FloatArray,
) -> None:
    """One transition into the dynamics of the states of the belief it left from (``index``,
    ``prob``; ``phi = [1, z_before, u]``, ``z`` after): the peak one-step error per dimension
    (``peak``) takes the error of the most likely state's dynamics when they are learned
    (:data:`SETTLED`), then weighted recursive least squares on the change
    ``z - z_before``, every dimension sharing the state's covariance."""
    d = z.shape[0]
    change = np.empty(d)
    for k in range(d):
        change[k] = z[k] - phi[k + 1]
    home = index[np.argmax(prob)]
    if cov[home, 0, 0] < SETTLED:
        for k in range(d):
            error = change[k]
            for r in range(phi.shape[0]):
                error -= dynamics[home, k, r] * phi[r]
            peak[k] = max(abs(error), peak[k] * (1.0 - PEAK_DECAY))
    weighted_rls(dynamics, cov, index, prob, phi, change, MIN_WEIGHT)


@njit(cache=True)
def add_failure(
    points: FloatArray, counts: IntArray, criterion: int, z: FloatArray, radius: float
) -> None:
    """Keep ``z`` among ``criterion``'s failure observations, unless a kept one lies within
    half the radius; once full, the oldest kept is replaced (``counts`` holds, per criterion,
    the points kept and the next slot to write)."""
    kept = counts[criterion, 0]
    near = (0.5 * radius) ** 2
    for f in range(kept):
        d2 = 0.0
        for r in range(z.shape[0]):
            diff = z[r] - points[criterion, f, r]
            d2 += diff * diff
        if d2 <= near:
            return
    slot = counts[criterion, 1]
    points[criterion, slot, :] = z
    counts[criterion, 0] = min(kept + 1, points.shape[1])
    counts[criterion, 1] = (slot + 1) % points.shape[1]


@njit(cache=True)
def _closest(
    points: FloatArray,
    kept: int,
    c: int,
    p: FloatArray,
    v: FloatArray,
    u_low: float,
    u_high: float,
    radius: float,
    midpoints: FloatArray,
    nearest: FloatArray,
) -> None:
    """``nearest[a]``: the least squared distance from ``p + v u_a`` to criterion c's
    failure points, counting only the points within ``radius`` of the path's segment (u in
    ``[u_low, u_high]``; others stay at their value)."""
    d = p.shape[0]
    vv = 0.0
    for r in range(d):
        vv += v[r] * v[r]
    reach2 = radius * radius
    for f in range(kept):
        wv = ww = 0.0
        for r in range(d):
            w = p[r] - points[c, f, r]
            wv += w * v[r]
            ww += w * w
        # |w + v u|^2 = ww + 2 u wv + u^2 vv, least at u = -wv / vv within the segment
        u = u_low if vv == 0.0 else min(max(-wv / vv, u_low), u_high)
        if ww + 2.0 * u * wv + u * u * vv > reach2:
            continue
        for a in range(midpoints.shape[0]):
            u = midpoints[a]
            nearest[a] = min(nearest[a], max(ww + 2.0 * u * wv + u * u * vv, 0.0))


@njit(cache=True)
def risk(
    motion: Any,
    extent: FloatArray,
    midpoints: FloatArray,
    index: IntArray,
    prob: FloatArray,
    z: FloatArray,
    safe: IntArray,
    out: FloatArray,
) -> None:
    """``out`` (bins x criteria): each action's reach risk at ``z`` under the belief
    (``index``, ``prob``), see the module docstring: the larger of its closeness to the
    failure points and, for a criterion with a bound (``bounds``, :func:`no_bounds`), how
    early the box of its worst cases reaches the bound (:func:`crossings`); 0 for a criterion
    with neither. Each step of the path is checked against the failure points only where the
    segment of all bins' points comes within the failures' box widened by the radius.

    ``motion`` is what the reach learned (the last item of
    :meth:`app.core.local_risk.LocalRisk.arrays`): its horizon and radius,
    the dynamics and their covariances, the peak one-step error, the failure points, their
    counts and the bounds; ``extent`` the box of the observations seen."""
    horizon, radius, dynamics, _, peak, points, counts, bounds = motion
    d, q = z.shape[0], midpoints.shape[0]
    model = np.zeros((d, d + 2))  # the belief's blend of its states' dynamics
    for t in range(index.shape[0]):
        for k in range(d):
            for r in range(d + 2):
                model[k, r] += prob[t] * dynamics[index[t], k, r]
    p, v, step = np.empty(d), np.empty(d), np.empty(d)
    low, high, nearest, when = np.empty(d), np.empty(d), np.empty(q), np.empty(q)
    u_low, u_high = midpoints[0], midpoints[q - 1]
    for c in range(safe.shape[0]):
        kept, b = counts[c, 0], int(bounds[c, 0])
        out[:, c] = 0.0
        # the continuation: the safe end of the range, or its middle without a direction
        u_safe = (u_low if safe[c] < 0 else u_high) if safe[c] != 0 else 0.5 * (u_low + u_high)
        if b >= 0:
            crossings(
                model,
                peak,
                extent,
                z,
                midpoints,
                u_safe,
                b,
                bounds[c, 1],
                bounds[c, 2],
                horizon,
                when,
            )
            # a bound tells the actions apart and adds no risk that every action shares: the
            # latest crossing counts as none
            latest = when.max()
            for a in range(q):
                out[a, c] = (latest - when[a]) / (horizon + 1)
        if kept == 0:
            continue
        low[:] = math.inf
        high[:] = -math.inf
        for f in range(kept):
            for r in range(d):
                low[r] = min(low[r], points[c, f, r] - radius)
                high[r] = max(high[r], points[c, f, r] + radius)
        # after the first step the path is p + v u_a: p from [1, z], v the action's column
        for k in range(d):
            p[k] = z[k] + model[k, 0]
            for r in range(d):
                p[k] += model[k, r + 1] * z[r]
            v[k] = model[k, d + 1]
        for _ in range(horizon):
            inside = True
            for r in range(d):
                first, last = p[r] + v[r] * u_low, p[r] + v[r] * u_high
                if max(first, last) < low[r] or min(first, last) > high[r]:
                    inside = False
            if inside:
                nearest[:] = math.inf
                _closest(points, kept, c, p, v, u_low, u_high, radius, midpoints, nearest)
                for a in range(q):
                    if nearest[a] < math.inf:
                        closeness = 1.0 - math.sqrt(nearest[a]) / radius
                        out[a, c] = max(out[a, c], closeness)
            # one more step under the safe bin: p <- p + W [1, p, u_safe], v <- v + W_z v
            for k in range(d):
                step[k] = model[k, 0] + model[k, d + 1] * u_safe
                for r in range(d):
                    step[k] += model[k, r + 1] * p[r]
            for k in range(d):
                p[k] += step[k]
            for k in range(d):
                step[k] = 0.0
                for r in range(d):
                    step[k] += model[k, r + 1] * v[r]
            for k in range(d):
                v[k] += step[k]


@njit(cache=True)
def crossings(
    model: FloatArray,
    peak: FloatArray,
    extent: FloatArray,
    z: FloatArray,
    midpoints: FloatArray,
    u_safe: float,
    b: int,
    below: float,
    above: float,
    horizon: int,
    when: FloatArray,
) -> None:
    """``when[a]``: when the box of the worst cases of bin a reaches ``below`` or ``above``
    on dimension ``b``, in steps from ``z`` (interpolated within the step; 0 when ``z`` is
    there already, ``horizon + 1`` when the box does not get there in ``horizon`` steps). Each
    bin's box starts at ``z`` and takes one step under its midpoint, the rest under
    ``u_safe``, of ``model`` (``x + W [1, x, u]``, interval arithmetic); each step widens every
    dimension but ``b`` by its ``peak`` and keeps it within ``extent`` (rows: lowest, highest
    seen; an empty one, low above high, keeps nothing), stretched to hold ``z``. The bins'
    boxes go side by side (dimension x bin), so that each step is a few loops over the bins."""
    d, q = z.shape[0], midpoints.shape[0]
    if z[b] <= below or z[b] >= above:
        when[:] = 0.0
        return
    when[:] = horizon + 1.0
    lo, hi = np.empty((d, q)), np.empty((d, q))
    next_lo, next_hi = np.empty((d, q)), np.empty((d, q))
    gain = np.empty((d, d))  # A = I + W_z
    floor, ceiling, kept = np.empty(d), np.empty(d), np.empty(d, dtype=np.bool_)
    for k in range(d):
        lo[k, :] = z[k]
        hi[k, :] = z[k]
        for r in range(d):
            gain[k, r] = model[k, r + 1] + (1.0 if r == k else 0.0)
        kept[k] = k != b and extent[0, k] <= extent[1, k]
        floor[k], ceiling[k] = min(extent[0, k], z[k]), max(extent[1, k], z[k])
    left = q  # the bins whose box has not reached the bound
    for t in range(horizon):
        for k in range(d):
            widen = 0.0 if k == b else peak[k]
            for a in range(q):
                base = model[k, 0] + model[k, d + 1] * (midpoints[a] if t == 0 else u_safe)
                next_lo[k, a], next_hi[k, a] = base - widen, base + widen
            for r in range(d):
                g = gain[k, r]
                if g >= 0.0:
                    for a in range(q):
                        next_lo[k, a] += g * lo[r, a]
                        next_hi[k, a] += g * hi[r, a]
                else:
                    for a in range(q):
                        next_lo[k, a] += g * hi[r, a]
                        next_hi[k, a] += g * lo[r, a]
        for a in range(q):
            if when[a] <= horizon:
                continue  # reached before
            first = math.inf
            if next_lo[b, a] <= below:
                first = t + (lo[b, a] - below) / (lo[b, a] - next_lo[b, a])
            if next_hi[b, a] >= above:
                first = min(first, t + (above - hi[b, a]) / (next_hi[b, a] - hi[b, a]))
            if first < math.inf:
                when[a] = first
                left -= 1
        if left == 0:
            return
        for k in range(d):
            for a in range(q):
                lo[k, a], hi[k, a] = next_lo[k, a], next_hi[k, a]
                if kept[k]:
                    lo[k, a] = min(max(lo[k, a], floor[k]), ceiling[k])
                    hi[k, a] = min(max(hi[k, a], floor[k]), ceiling[k])
