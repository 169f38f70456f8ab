"""Plain numpy readings of the compiled kernels' equations, for the tests only: each kernel
must give their numbers, bit for bit, on random inputs, on any CPU.

So no reading here leans on arithmetic whose last bits follow the CPU: ``exp`` and ``log`` of
an array go through Python's ``math`` (libm, as the kernels do) rather than numpy's SIMD loops,
and a sum the kernels take pairwise is taken by :func:`pairwise_sum`, written out in Python.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]


def exp(x: FloatArray) -> FloatArray:
    """``exp`` of every element through libm, as the kernels take it."""
    return np.array([math.exp(v) for v in np.ravel(x)]).reshape(np.shape(x))


def pairwise_sum(x: Sequence[float] | FloatArray) -> float:
    """The sum in the kernels' fixed pairwise order (``app.core._kernels.pairwise_sum``):
    one by one below 8, eight running sums up to 128 (then the rest one by one), and a longer
    run halved at a multiple of 8, each half summed so and the two added."""
    values = [float(v) for v in x]
    n = len(values)
    if n < 8:
        total = -0.0
        for v in values:
            total += v
        return total
    if n <= 128:
        sums = values[:8]
        whole = n - n % 8
        for i in range(8, whole, 8):
            for lane in range(8):
                sums[lane] += values[i + lane]
        total = ((sums[0] + sums[1]) + (sums[2] + sums[3])) + (
            (sums[4] + sums[5]) + (sums[6] + sums[7])
        )
        for v in values[whole:]:
            total += v
        return total
    half = n // 2
    half -= half % 8
    return pairwise_sum(values[:half]) + pairwise_sum(values[half:])


def monotone(q_table: FloatArray, directions: Sequence[str | None]) -> FloatArray:
    """The running maximum of each criterion's risk from its safe end of the action range
    (a criterion without a direction as it is)."""
    out = q_table.copy()
    for c, direction in enumerate(directions):
        if direction == "decrease":
            np.maximum.accumulate(q_table[:, :, c], axis=1, out=out[:, :, c])
        elif direction == "increase":
            out[:, ::-1, c] = np.maximum.accumulate(q_table[:, ::-1, c], axis=1)
    return out


def decide(
    local: FloatArray,
    reached: FloatArray | None,
    proposed_bin: int,
    threshold: float,
    margin: float,
) -> tuple[float, int, int]:
    """The decision on one table: each criterion's risk the mean of the local model's and
    the reach's (the local alone without the reach), the total ``1 - prod(1 - risk)``; the
    limit the threshold or the least total plus the margin; the proposal when within it,
    else the nearest bin within it, the less risky of two equally near. Returns the limit, the
    proposal's verdict (-1: within the limit) and the bin to apply."""
    risks = local if reached is None else (local + reached) / 2
    total = 1 - np.prod(1 - np.clip(risks, 0, 1), axis=1)
    limit = max(threshold, float(total.min()) + margin)
    verdict = -1 if total[proposed_bin] <= limit else int(risks[proposed_bin].argmax())
    allowed = np.flatnonzero(total <= limit)
    order = np.lexsort((total[allowed], np.abs(allowed - proposed_bin)))
    return limit, verdict, int(allowed[order[0]])


def recognise(
    sq_distances: FloatArray, variances: FloatArray, k: int
) -> tuple[IntArray, FloatArray]:
    """Eq. 1 as a softmax of ``-d^2 / var`` over the top k states (app.core.belief)."""
    logits = -sq_distances / variances
    index = np.flatnonzero(logits >= logits.max() + np.log(np.finfo(np.float64).eps))
    if sq_distances.shape[0] <= k:
        index = np.arange(sq_distances.shape[0])
    elif index.size > k:  # the k largest, ties to the lower index
        index = np.sort(index[np.argsort(-logits[index], kind="stable")[:k]])
    weights = exp(logits[index] - logits[index].max())
    keep = weights > 0.0
    return index[keep], weights[keep] / pairwise_sum(weights[keep])


def cluster(
    state: dict[str, FloatArray], z: FloatArray, epsilon: float, rho: float, max_states: int
) -> str:
    """One eTS+ step with the radius spread (app.core.clustering) on plain arrays in
    ``state`` (centres, potentials, radii, support, scatter, beta, sigma, k)."""
    state["k"] += 1
    k, theta = state["k"], float(np.sum(z * z))
    centres = state["centres"]
    if not len(centres):
        state.update(
            centres=z[None],
            potentials=np.ones(1),
            radii=np.full(1, epsilon),
            support=np.ones(1),
            scatter=np.zeros(1),
        )
        kind = "new"
    else:
        d2 = np.maximum(
            np.sum(centres * centres, axis=1) - 2.0 * np.sum(centres * z, axis=1) + theta, 0.0
        )
        nu = float(np.sum(z * state["beta"]))
        p_new = (k - 1) / ((k - 1) * (theta + 1.0) + state["sigma"] - 2.0 * nu)
        pot = state["potentials"] = (
            (k - 1) * state["potentials"] / (k - 2 + state["potentials"] * (1.0 + d2))
        )
        nearest = int(d2.argmin())
        candidate = p_new > pot.max() or p_new < pot.min()
        if candidate and np.sqrt(d2[nearest]) < epsilon:
            centres[nearest], pot[nearest] = z, p_new
            kind = "replaced"
        elif candidate and len(centres) < max_states:
            state["centres"] = np.vstack([centres, z])
            for name, value in (
                ("potentials", p_new),
                ("radii", epsilon),
                ("support", 1.0),
                ("scatter", 0.0),
            ):
                state[name] = np.append(state[name], value)
            kind = "new"
        else:
            state["support"][nearest] += 1
            state["scatter"][nearest] += d2[nearest]
            local = np.sqrt(state["scatter"][nearest] / state["support"][nearest])
            state["radii"][nearest] = rho * state["radii"][nearest] + (1.0 - rho) * local
            kind = "assigned"
    state["beta"] = state["beta"] + z
    state["sigma"] += theta
    return kind


def reach(
    dynamics: FloatArray,
    prob: FloatArray,
    z: FloatArray,
    midpoints: FloatArray,
    safe_bin: int,
    points: FloatArray,
    horizon: int,
    radius: float,
    peak: FloatArray | None = None,
    extent: FloatArray | None = None,
    bound: tuple[int, float, float] | None = None,
) -> FloatArray:
    """Each bin's reach risk for one criterion (app.core.reach): the belief's blend of the
    states' dynamics, one step under the bin, then ``horizon - 1`` under ``safe_bin``, each
    point's closeness ``max(0, 1 - distance / radius)`` to the nearest failure point; with a
    ``bound`` (dimension, below, above), ``(max tau - tau) / (horizon + 1)``, ``tau`` when
    the box of worst cases (intervals through ``A = I + W_z``, every dimension but the
    bound's widened by ``peak`` and kept within ``extent`` stretched to hold z) first
    reaches it, interpolated within the step."""
    model = np.einsum("i,ikr->kr", prob, dynamics)
    out = np.zeros(midpoints.shape[0])
    taus = np.zeros(midpoints.shape[0])
    for a, u in enumerate(midpoints):
        x = z.copy()
        for t in range(horizon):
            x = x + model @ np.concatenate(([1.0], x, [u if t == 0 else midpoints[safe_bin]]))
            if points.shape[0]:
                distance = np.sqrt(((points - x) ** 2).sum(axis=1)).min()
                out[a] = max(out[a], 1.0 - distance / radius)
        if bound is not None:
            assert peak is not None and extent is not None
            taus[a] = _crossing(model, peak, extent, z, u, midpoints[safe_bin], bound, horizon)
    if bound is not None:  # what the latest crossing shares with the others counts as none
        out = np.maximum(out, (taus.max() - taus) / (horizon + 1))
    return out


def _crossing(
    model: FloatArray,
    peak: FloatArray,
    extent: FloatArray,
    z: FloatArray,
    u: float,
    u_safe: float,
    bound: tuple[int, float, float],
    horizon: int,
) -> float:
    b, below, above = bound
    d = z.shape[0]
    gains = np.eye(d) + model[:, 1 : d + 1]
    up, down = np.maximum(gains, 0.0), np.minimum(gains, 0.0)
    widen = peak.copy()
    widen[b] = 0.0
    keep = (np.arange(d) != b) & (extent[0] <= extent[1])  # (an empty extent keeps nothing)
    floor, ceiling = np.minimum(extent[0], z), np.maximum(extent[1], z)
    lo, hi = z.copy(), z.copy()
    if z[b] <= below or z[b] >= above:
        return 0.0
    for t in range(horizon):
        base = model[:, 0] + model[:, d + 1] * (u if t == 0 else u_safe)
        new_lo = base - widen + up @ lo + down @ hi
        new_hi = base + widen + up @ hi + down @ lo
        times = [np.inf]
        if new_lo[b] <= below:
            times.append(t + (lo[b] - below) / (lo[b] - new_lo[b]))
        if new_hi[b] >= above:
            times.append(t + (above - hi[b]) / (new_hi[b] - hi[b]))
        if min(times) < np.inf:
            return float(min(times))
        lo = np.where(keep, np.clip(new_lo, floor, ceiling), new_lo)
        hi = np.where(keep, np.clip(new_hi, floor, ceiling), new_hi)
    return horizon + 1.0
