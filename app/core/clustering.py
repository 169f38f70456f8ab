"""Online state determination: evolving clustering with recursive potentials (docs/algorithm.md).

Each cluster centre is a state of the e-FSM. States are only ever added or moved, never removed
or renumbered, so the transition matrices and flags can index them for the model's whole life.
All distances are in normalised units (see :class:`~app.core.config.ObservationSpec`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import numpy.typing as npt
from numba import njit

from app.core import _stored as stored
from app.core._arrays import ensure_capacity
from app.core.belief import Belief, _recognise
from app.core.config import ClusteringConfig
from app.core.errors import InvalidSnapshot

FloatArray = npt.NDArray[np.float64]


@dataclass(slots=True)
class StateUpdate:
    """What one observation did to the state set.

    ``kind`` is ``new`` (a state was created), ``replaced`` (the nearest centre moved onto the
    observation) or ``assigned`` (the nearest state absorbed it and widened its spread).
    """

    kind: Literal["new", "replaced", "assigned"]
    index: int

    @property
    def is_new(self) -> bool:
        """True when this observation created a state."""
        return self.kind == "new"


# rows of the per-state numbers (EvolvingClusterer.stats) and of its counts
SQ_NORM, POTENTIAL, RADIUS, SCATTER, VARIANCE = range(5)
SAMPLES, STATES, CAPACITY_HITS = range(3)


class EvolvingClusterer:
    """eTS / eTS+ evolving clustering of normalised observations (docs/algorithm.md).

    The potential of a point is its inverse mean squared distance to all earlier samples,
    ``P_k(z) = 1 / (1 + mean_l ||z - z_l||^2)``, kept recursively in O(d) memory.

    Everything a step changes lives in arrays, so that a compiled step can take them whole:
    the centres (dimension x state: the distances vectorise), the per-state numbers
    (``stats``: squared norm, potential, radius, scatter and variance, one row each), the
    support, the running sums (``sums``: beta, the sum of earlier samples, then sigma, the sum
    of their squared norms) and the counts (samples, states, capacity hits).
    """

    def __init__(self, config: ClusteringConfig, dim: int, max_states: int) -> None:
        self.config = config
        self.dim = dim
        self.max_states = max_states
        self.counts = np.zeros(3, dtype=np.int64)
        self.sums = np.zeros(dim + 1)
        self.params = np.array([config.epsilon, config.rho, config.min_variance])
        self.modes = np.array(
            [config.creation_rule == "ets_plus", _SPREADS[config.spread], max_states],
            dtype=np.int64,
        )
        self.centres_t = np.zeros((dim, 0))
        self.stats = np.zeros((5, 0))
        self.support_counts = np.zeros(0, dtype=np.int64)
        self._arrays: tuple[Any, ...] | None = None  # see arrays

    @property
    def k(self) -> int:
        """Samples seen, never reset between episodes."""
        return int(self.counts[SAMPLES])

    @property
    def n_states(self) -> int:
        """Number of states (cluster centres)."""
        return int(self.counts[STATES])

    @property
    def capacity_hits(self) -> int:
        """Observations that would have made a state beyond ``max_states``."""
        return int(self.counts[CAPACITY_HITS])

    @property
    def centres(self) -> FloatArray:
        """Cluster centres, one row per state, normalised units (read-only view)."""
        view = self.centres_t[:, : self.n_states].T
        view.flags.writeable = False
        return view

    @property
    def potentials(self) -> FloatArray:
        """Potential of every centre."""
        return self.stats[POTENTIAL, : self.n_states].copy()

    @property
    def radii(self) -> FloatArray:
        """Zone-of-influence radius of every state (starts at epsilon, smoothed with rho)."""
        return self.stats[RADIUS, : self.n_states].copy()

    @property
    def support(self) -> npt.NDArray[np.int64]:
        """Observations absorbed by each state (the sample that created it included)."""
        return self.support_counts[: self.n_states].copy()

    def variances(self) -> FloatArray:
        """var(s^i) of Eq. 1 per state (docs/algorithm.md), read-only view."""
        view = self.stats[VARIANCE, : self.n_states]
        view.flags.writeable = False
        return view

    def sq_distances(self, z: FloatArray) -> FloatArray:
        """Squared distances from z to every centre: ||c||^2 - 2 c.z + ||z||^2, clipped at 0."""
        n = self.n_states
        out = np.empty(n)
        _sq_distances(self.centres_t, self.stats[SQ_NORM], n, z, _dot(z, z), out)
        return out

    def learn_one(self, z: FloatArray) -> StateUpdate:
        """Cluster one normalised observation; may create or move one state."""
        return self.learn_and_recognise(z, 1)[0]

    def learn_and_recognise(self, z: FloatArray, k: int) -> tuple[StateUpdate, Belief]:
        """Cluster one normalised observation (it may create or move one state), then the
        belief over the states after it (Eq. 1, top ``k``): one compiled call."""
        self.make_room()
        size = min(self.n_states + 1, k)
        index = np.empty(size, dtype=np.int64)
        prob = np.empty(size)
        kind, at, m = learn_and_recognise(z, self.arrays(), k, index, prob)
        return StateUpdate(_KINDS[kind], at), Belief(index[:m], prob[:m])

    def arrays(
        self,
    ) -> tuple[
        FloatArray,
        FloatArray,
        npt.NDArray[np.int64],
        FloatArray,
        npt.NDArray[np.int64],
        FloatArray,
        npt.NDArray[np.int64],
    ]:
        """What a compiled step clusters with (:func:`learn_and_recognise`'s arrays, in
        order): the same tuple until :meth:`make_room` replaces them."""
        if self._arrays is None:
            self._arrays = (
                self.centres_t,
                self.stats,
                self.support_counts,
                self.sums,
                self.counts,
                self.params,
                self.modes,
            )
        return self._arrays

    def make_room(self) -> None:
        """Room for one more state."""
        n = self.n_states
        if n < self.centres_t.shape[1]:
            return
        limit = self.max_states
        self.centres_t = ensure_capacity(self.centres_t, n + 1, limit, axis=1)
        self.stats = ensure_capacity(self.stats, n + 1, limit, axis=1)
        self.support_counts = ensure_capacity(self.support_counts, n + 1, limit)
        self._arrays = None

    def snapshot(self) -> dict[str, Any]:
        """Exact state as plain data and arrays."""
        n = self.n_states
        return {
            "k": self.k,
            "beta": self.sums[: self.dim].copy(),
            "sigma": float(self.sums[self.dim]),
            "capacity_hits": self.capacity_hits,
            "centres": self.centres_t[:, :n].T.copy(),
            "sq_norms": self.stats[SQ_NORM, :n].copy(),
            "potentials": self.stats[POTENTIAL, :n].copy(),
            "radii": self.stats[RADIUS, :n].copy(),
            "support": self.support_counts[:n].copy(),
            "scatter": self.stats[SCATTER, :n].copy(),
        }

    @classmethod
    def restore(
        cls, config: ClusteringConfig, dim: int, max_states: int, data: dict[str, Any]
    ) -> EvolvingClusterer:
        """Rebuild a clusterer from :meth:`snapshot` output, every part checked."""
        self = cls(config, dim, max_states)
        self.counts[SAMPLES] = stored.integer(data["k"], "clustering.k")
        self.sums[:dim] = stored.floats(data["beta"], "clustering.beta", (dim,))
        self.sums[dim] = stored.real(data["sigma"], "clustering.sigma", low=0.0)
        self.counts[CAPACITY_HITS] = stored.integer(
            data["capacity_hits"], "clustering.capacity_hits"
        )
        centres = stored.floats(data["centres"], "clustering.centres")
        n = centres.size // dim if dim else 0
        if centres.shape not in ((n, dim), (n * dim,)) or n > max_states:
            raise InvalidSnapshot(
                f"expected at most {max_states} centres of {dim} numbers",
                field="clustering.centres",
            )
        self.counts[STATES] = n
        self.centres_t = np.ascontiguousarray(centres.reshape(n, dim).T)
        self.stats = np.zeros((5, n))
        self.stats[SQ_NORM] = stored.floats(data["sq_norms"], "clustering.sq_norms", (n,), low=0.0)
        norms = (centres.reshape(n, dim) ** 2).sum(axis=1)
        if not np.allclose(self.stats[SQ_NORM], norms, rtol=1e-9, atol=1e-12):
            raise InvalidSnapshot("a squared norm is not its centre's", field="clustering.sq_norms")
        # P = 1 / (1 + mean squared distance): in (0, 1], up to the recursion's rounding (a
        # point seen twice in a row gives 1 + 2^-52)
        self.stats[POTENTIAL] = stored.floats(
            data["potentials"], "clustering.potentials", (n,), low=0.0, high=1.0 + 1e-9
        )
        self.stats[RADIUS] = stored.floats(data["radii"], "clustering.radii", (n,), low=0.0)
        self.support_counts = stored.ints(data["support"], "clustering.support", (n,), low=1)
        self.stats[SCATTER] = stored.floats(data["scatter"], "clustering.scatter", (n,), low=0.0)
        spread = _SPREADS[config.spread]
        for i in range(n):
            _refresh_variance(
                self.stats[VARIANCE],
                self.stats[RADIUS],
                self.support_counts,
                self.stats[SCATTER],
                i,
                spread,
                config.epsilon,
                config.min_variance,
            )
        return self


NEW, REPLACED, ASSIGNED = 0, 1, 2
_KINDS: dict[int, Literal["new", "replaced", "assigned"]] = {
    NEW: "new",
    REPLACED: "replaced",
    ASSIGNED: "assigned",
}
_SPREADS = {"radius": 0, "member_variance": 1, "ets2004": 2}


@njit(cache=True)
def _dot(x: FloatArray, y: FloatArray) -> float:
    total = 0.0
    for i in range(x.shape[0]):
        total += x[i] * y[i]
    return total


@njit(cache=True)
def _sq_distances(
    centres: FloatArray, sq_norms: FloatArray, n: int, z: FloatArray, theta: float, out: FloatArray
) -> None:
    """``out[i] = max(||c_i||^2 - 2 c_i.z + theta, 0)`` for the first n centres (dimension
    x state); each dot product summed over the dimensions in order, a dimension at a time
    across all states so that the loops vectorise."""
    for i in range(n):
        out[i] = 0.0
    for j in range(z.shape[0]):
        zj, row = z[j], centres[j]
        for i in range(n):
            out[i] += row[i] * zj
    for i in range(n):
        d2 = sq_norms[i] - 2.0 * out[i] + theta
        out[i] = d2 if d2 > 0.0 else 0.0


@njit(cache=True)
def learn_and_recognise(
    z: FloatArray,
    arrays: Any,
    top: int,
    index: npt.NDArray[np.int64],
    prob: FloatArray,
) -> tuple[int, int, int]:
    """:meth:`EvolvingClusterer.learn_and_recognise` on its ``arrays``
    (:meth:`EvolvingClusterer.arrays`, room for one more state): :func:`_learn`, then
    :func:`~app.core.belief._recognise` on the states after it, into ``index`` and ``prob``.
    Returns the update's kind, the state it touched and the belief's size."""
    stats, sums, counts = arrays[1], arrays[3], arrays[4]
    counts[SAMPLES] += 1
    n, d = counts[STATES], z.shape[0]
    d2 = np.empty(n + 1)
    kind, at, sigma, hit = _learn(z, arrays, n, d2)
    sums[d] = sigma
    counts[CAPACITY_HITS] += hit
    if kind == NEW:
        n += 1
        counts[STATES] = n
    m = _recognise(d2[:n], stats[VARIANCE, :n], top, index, prob)
    return kind, at, m


@njit(cache=True)
def _refresh_variance(
    variances: FloatArray,
    radii: FloatArray,
    support: npt.NDArray[np.int64],
    scatter: FloatArray,
    i: int,
    spread: int,
    epsilon: float,
    min_variance: float,
) -> None:
    """var(s^i) of Eq. 1: r_i^2 (radius), the mean squared member distance
    (member_variance) or eTS-2004's r^2 / 4 for membership exp(-4 d^2 / r^2), floored."""
    if spread == 0:
        var = radii[i] ** 2
    elif spread == 1:
        var = scatter[i] / support[i]
    else:
        var = epsilon**2 / 4.0
    variances[i] = max(var, min_variance)


@njit(cache=True, error_model="numpy")  # no divisor is 0; without the check the loops vectorise
def _learn(z: FloatArray, arrays: Any, n: int, d2: FloatArray) -> tuple[int, int, float, int]:
    """One eTS / eTS+ step on the clusterer's ``arrays`` (capacity for n + 1 states): the
    update's kind, the state it touched, the new sigma and whether a candidate met the state
    limit. ``d2`` gets the squared distances to every centre after the update."""
    centres, stats, support, sums, counts, params, modes = arrays
    d = z.shape[0]
    k, beta, sigma = counts[SAMPLES], sums[:d], float(sums[d])
    sq_norms, potentials, radii = stats[SQ_NORM], stats[POTENTIAL], stats[RADIUS]
    scatter, variances = stats[SCATTER], stats[VARIANCE]
    max_states, ets_plus, spread = modes[2], modes[0] == 1, modes[1]
    epsilon, rho, min_variance = params[0], params[1], params[2]
    theta = _dot(z, z)
    index, kind, hit = 0, NEW, 0
    if n == 0:  # first sample: centre 1 with potential 1
        _add(z, theta, 1.0, 0, arrays)
        d2[0] = 0.0
    else:
        _sq_distances(centres, sq_norms, n, z, theta, d2)
        # P_k(z_k) = (k-1) / ((k-1)(theta+1) + sigma - 2 nu)
        nu = _dot(z, beta)
        p_new = (k - 1) / ((k - 1) * (theta + 1.0) + sigma - 2.0 * nu)
        # P_k(c_i) = (k-1) P_{k-1}(c_i) / (k-2 + P_{k-1}(c_i) (1 + d_i^2))
        for i in range(n):  # apart from the reductions below, so that it vectorises
            potentials[i] = (k - 1) * potentials[i] / (k - 2 + potentials[i] * (1.0 + d2[i]))
        nearest, p_max, p_min = 0, -math.inf, math.inf
        for i in range(n):
            p_max, p_min = max(p_max, potentials[i]), min(p_min, potentials[i])
            if d2[i] < d2[nearest]:
                nearest = i
        delta = math.sqrt(d2[nearest])
        if ets_plus:  # eTS+: novel if above all or below all
            candidate = p_new > p_max or p_new < p_min
            replace = delta < epsilon
        else:  # eTS-2004: only dense points; replace when P/Pmax - delta/r >= 1
            candidate = p_new > p_max
            replace = p_new / p_max - delta / epsilon >= 1.0
        if candidate and replace:
            centres[:, nearest] = z
            sq_norms[nearest] = theta
            potentials[nearest] = p_new
            _sq_distances(centres, sq_norms, n, z, theta, d2)
            index, kind = nearest, REPLACED
        elif candidate and n < max_states:
            _add(z, theta, p_new, n, arrays)
            d2[n] = 0.0
            index = n
        else:
            hit = 1 if candidate else 0
            # scatter_i += ||z - c_i||^2; r_i = rho r_i + (1 - rho) sqrt(scatter_i / N_i)
            support[nearest] += 1
            scatter[nearest] += d2[nearest]
            local = math.sqrt(scatter[nearest] / support[nearest])
            radii[nearest] = rho * radii[nearest] + (1.0 - rho) * local
            _refresh_variance(
                variances, radii, support, scatter, nearest, spread, epsilon, min_variance
            )
            index, kind = nearest, ASSIGNED
    for i in range(beta.shape[0]):
        beta[i] += z[i]
    return kind, index, sigma + theta, hit


@njit(cache=True)
def _add(z: FloatArray, theta: float, potential: float, n: int, arrays: Any) -> None:
    """State ``n`` at ``z`` (its squared norm ``theta``) with ``potential``, in the
    clusterer's ``arrays``."""
    centres, stats, support, _, _, params, modes = arrays
    sq_norms, potentials, radii = stats[SQ_NORM], stats[POTENTIAL], stats[RADIUS]
    scatter, variances = stats[SCATTER], stats[VARIANCE]
    epsilon, spread, min_variance = params[0], modes[1], params[2]
    centres[:, n] = z
    sq_norms[n] = theta
    potentials[n] = potential
    radii[n] = epsilon  # initial spread = epsilon
    support[n] = 1
    scatter[n] = 0.0
    _refresh_variance(variances, radii, support, scatter, n, spread, epsilon, min_variance)
