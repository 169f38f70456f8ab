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

from app.core import _stored as stored
from app.core._arrays import ensure_capacity
from app.core.config import ClusteringConfig
from app.core.errors import InvalidSnapshot

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class StateUpdate:
    """What one observation did to the state set.

    ``kind`` is ``new`` (a state was created), ``replaced`` (the nearest centre moved onto the
    observation) or ``assigned`` (the nearest state absorbed it and widened its spread).
    ``sq_distances`` are the squared distances from the observation to every centre *after*
    the update, ready for recognition (Eq. 1).
    """

    kind: Literal["new", "replaced", "assigned"]
    index: int
    sq_distances: FloatArray

    @property
    def is_new(self) -> bool:
        """True when this observation created a state."""
        return self.kind == "new"


class EvolvingClusterer:
    """eTS / eTS+ evolving clustering of normalised observations (docs/algorithm.md).

    The potential of a point is its inverse mean squared distance to all earlier samples,
    ``P_k(z) = 1 / (1 + mean_l ||z - z_l||^2)``, kept recursively in O(d) memory.
    """

    def __init__(self, config: ClusteringConfig, dim: int, max_states: int) -> None:
        self.config = config
        self.dim = dim
        self.max_states = max_states
        self.k = 0  # samples seen, never reset between episodes
        self.beta = np.zeros(dim)  # sum of earlier samples
        self.sigma = 0.0  # sum of their squared norms
        self.capacity_hits = 0
        self._n = 0
        self._centres = np.zeros((0, dim))
        self._sq_norms = np.zeros(0)
        self._potentials = np.zeros(0)
        self._radii = np.zeros(0)
        self._support = np.zeros(0, dtype=np.int64)
        self._scatter = np.zeros(0)
        self._variances = np.zeros(0)

    @property
    def n_states(self) -> int:
        """Number of states (cluster centres)."""
        return self._n

    @property
    def centres(self) -> FloatArray:
        """Cluster centres, one row per state, normalised units (read-only view)."""
        view = self._centres[: self._n]
        view.flags.writeable = False
        return view

    @property
    def potentials(self) -> FloatArray:
        """Potential of every centre."""
        return self._potentials[: self._n].copy()

    @property
    def radii(self) -> FloatArray:
        """Zone-of-influence radius of every state (starts at epsilon, smoothed with rho)."""
        return self._radii[: self._n].copy()

    @property
    def support(self) -> npt.NDArray[np.int64]:
        """Observations absorbed by each state (the sample that created it included)."""
        return self._support[: self._n].copy()

    def variances(self) -> FloatArray:
        """var(s^i) of Eq. 1 per state (docs/algorithm.md), read-only view."""
        view = self._variances[: self._n]
        view.flags.writeable = False
        return view

    def _refresh_variance(self, i: int) -> None:
        cfg = self.config
        if cfg.spread == "radius":  # r_i^2 with a floor
            var = self._radii[i] ** 2
        elif cfg.spread == "member_variance":  # mean squared member distance, floored
            var = self._scatter[i] / self._support[i]
        else:  # eTS-2004 membership exp(-4 d^2 / r^2): var = r^2 / 4
            var = cfg.epsilon**2 / 4.0
        self._variances[i] = max(var, cfg.min_variance)

    def sq_distances(self, z: FloatArray, sq_norm: float | None = None) -> FloatArray:
        """Squared distances from z to every centre: ||c||^2 - 2 c.z + ||z||^2, clipped at 0.

        ``sq_norm`` is ||z||^2 where the caller has it already.
        """
        n = self._n
        if sq_norm is None:
            sq_norm = float(z @ z)
        d2 = self._sq_norms[:n] - 2.0 * (self._centres[:n] @ z) + sq_norm
        return np.maximum(d2, 0.0, out=d2)

    def learn_one(self, z: FloatArray) -> StateUpdate:
        """Cluster one normalised observation; may create or move one state."""
        cfg = self.config
        self.k += 1
        k = self.k
        theta = float(z @ z)
        if self._n == 0:  # first sample: centre 1 with potential 1
            index = self._add(z, potential=1.0)
            self._accumulate(z, theta)
            return StateUpdate("new", index, np.zeros(1))

        n = self._n
        d2 = self.sq_distances(z, theta)
        # P_k(z_k) = (k-1) / ((k-1)(theta+1) + sigma - 2 nu)
        nu = float(z @ self.beta)
        p_new = (k - 1) / ((k - 1) * (theta + 1.0) + self.sigma - 2.0 * nu)
        # P_k(c_i) = (k-1) P_{k-1}(c_i) / (k-2 + P_{k-1}(c_i) (1 + d_i^2))
        pot = self._potentials[:n]
        pot[:] = (k - 1) * pot / (k - 2 + pot * (1.0 + d2))
        nearest = int(d2.argmin())
        delta = math.sqrt(d2[nearest])
        p_max = float(pot.max())

        if cfg.creation_rule == "ets_plus":  # eTS+: novel if above all or below all
            candidate = p_new > p_max or p_new < float(pot.min())
            replace = delta < cfg.epsilon
        else:  # eTS-2004: only dense points; replace when P/Pmax - delta/r >= 1
            candidate = p_new > p_max
            replace = p_new / p_max - delta / cfg.epsilon >= 1.0

        if candidate and replace:
            self._centres[nearest] = z
            self._sq_norms[nearest] = theta
            self._potentials[nearest] = p_new
            d2 = self.sq_distances(z, theta)
            update = StateUpdate("replaced", nearest, d2)
        elif candidate and n < self.max_states:
            index = self._add(z, potential=p_new)
            update = StateUpdate("new", index, np.append(d2, 0.0))
        else:
            if candidate:
                self.capacity_hits += 1
            self._assign(nearest, float(d2[nearest]))
            update = StateUpdate("assigned", nearest, d2)
        self._accumulate(z, theta)
        return update

    def _add(self, z: FloatArray, potential: float) -> int:
        n = self._n
        limit = self.max_states
        self._centres = ensure_capacity(self._centres, n + 1, limit)
        self._sq_norms = ensure_capacity(self._sq_norms, n + 1, limit)
        self._potentials = ensure_capacity(self._potentials, n + 1, limit)
        self._radii = ensure_capacity(self._radii, n + 1, limit)
        self._support = ensure_capacity(self._support, n + 1, limit)
        self._scatter = ensure_capacity(self._scatter, n + 1, limit)
        self._variances = ensure_capacity(self._variances, n + 1, limit)
        self._centres[n] = z
        self._sq_norms[n] = float(z @ z)
        self._potentials[n] = potential
        self._radii[n] = self.config.epsilon  # initial spread = epsilon
        self._support[n] = 1
        self._scatter[n] = 0.0
        self._n = n + 1
        self._refresh_variance(n)
        return n

    def _assign(self, index: int, sq_distance: float) -> None:
        # scatter_i += ||z - c_i||^2; r_i = rho r_i + (1 - rho) sqrt(scatter_i / N_i)
        rho = self.config.rho
        support = int(self._support[index]) + 1
        scatter = float(self._scatter[index]) + sq_distance
        self._support[index] = support
        self._scatter[index] = scatter
        local = math.sqrt(scatter / support)
        self._radii[index] = rho * float(self._radii[index]) + (1.0 - rho) * local
        self._refresh_variance(index)

    def _accumulate(self, z: FloatArray, sq_norm: float) -> None:
        self.beta += z
        self.sigma += sq_norm

    def snapshot(self) -> dict[str, Any]:
        """Exact state as plain data and arrays."""
        n = self._n
        return {
            "k": self.k,
            "beta": self.beta.copy(),
            "sigma": self.sigma,
            "capacity_hits": self.capacity_hits,
            "centres": self._centres[:n].copy(),
            "sq_norms": self._sq_norms[:n].copy(),
            "potentials": self._potentials[:n].copy(),
            "radii": self._radii[:n].copy(),
            "support": self._support[:n].copy(),
            "scatter": self._scatter[:n].copy(),
        }

    @classmethod
    def restore(
        cls, config: ClusteringConfig, dim: int, max_states: int, data: dict[str, Any]
    ) -> EvolvingClusterer:
        """Rebuild a clusterer from :meth:`snapshot` output, every part checked."""
        self = cls(config, dim, max_states)
        self.k = stored.integer(data["k"], "clustering.k")
        self.beta = stored.floats(data["beta"], "clustering.beta", (dim,))
        self.sigma = stored.real(data["sigma"], "clustering.sigma", low=0.0)
        self.capacity_hits = stored.integer(data["capacity_hits"], "clustering.capacity_hits")
        centres = stored.floats(data["centres"], "clustering.centres")
        n = centres.size // dim if dim else 0
        if centres.shape not in ((n, dim), (n * dim,)) or n > max_states:
            raise InvalidSnapshot(f"expected at most {max_states} centres of {dim} numbers",
                                  field="clustering.centres")
        self._n = n
        self._centres = centres.reshape(n, dim)
        self._sq_norms = stored.floats(data["sq_norms"], "clustering.sq_norms", (n,), low=0.0)
        self._potentials = stored.floats(data["potentials"], "clustering.potentials", (n,))
        self._radii = stored.floats(data["radii"], "clustering.radii", (n,), low=0.0)
        self._support = stored.ints(data["support"], "clustering.support", (n,), low=1)
        self._scatter = stored.floats(data["scatter"], "clustering.scatter", (n,), low=0.0)
        self._variances = np.zeros(self._n)
        for i in range(self._n):
            self._refresh_variance(i)
        return self
