"""The clustering space: physical observations to normalised units and back.

Each observed dimension is scaled to ``(x - low) / (high - low)``, a dimension with a knee
``k > 0`` first warped to ``x + clip(x, -k, k)`` (its first k count twice, so that states are
finer where small values matter, such as short headways); each configured feature (a linear
combination or a ratio of the observation, :class:`~app.core.config.Feature`) is clipped to its
range and scaled by it. The forward map runs on every step, compiled.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from numba import njit

from app.core.config import ObservationSpec

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]


class ObservationSpace:
    """The normalisation of one configuration's observations (and its inverse)."""

    def __init__(self, spec: ObservationSpec) -> None:
        self.dim = dim = spec.size
        features = spec.features
        self.raw = spec.cluster_raw
        self.size = dim * self.raw + len(features)  # dimensions of the clustering space
        self._feature_low = np.array([f.low for f in features], dtype=np.float64)
        self._feature_range = np.array([f.high - f.low for f in features], dtype=np.float64)
        # per feature: weights (dim), divide_by (dim), whether a ratio, floor, low, range
        self.features = np.array(
            [
                [
                    *f.weights,
                    *(f.divide_by or (0.0,) * dim),
                    bool(f.divide_by),
                    f.floor,
                    f.low,
                    f.high - f.low,
                ]
                for f in features
            ],
            dtype=np.float64,
        ).reshape(-1, 2 * dim + 4)
        knee = np.array(spec.knee or [0.0] * dim, dtype=np.float64)
        self._curved: BoolArray = knee > 0  # the dimensions with a knee
        self._knee = np.where(self._curved, knee, 1.0)
        low, high = np.array(spec.low, dtype=np.float64), np.array(spec.high, dtype=np.float64)
        self._low = low + np.where(self._curved, np.clip(low, -self._knee, self._knee), 0.0)
        self._range: FloatArray = high - low
        # per dimension: whether it has a knee, the knee, the (warped) low end, the range
        self.scales = np.stack(
            [self._curved.astype(np.float64), self._knee, self._low, self._range]
        )
        self._arrays = (self.raw, self.scales, self.features)

    def arrays(self) -> tuple[bool, FloatArray, FloatArray]:
        """What a compiled step normalises with (:func:`normalise`'s settings, in order)."""
        return self._arrays

    def normalise(self, observation: FloatArray) -> FloatArray:
        """Physical units (a float64 vector) to the clustering space."""
        z = np.empty(self.size)
        normalise(observation, self.raw, self.scales, self.features, z)
        return z

    def along(self, dimension: int, value: float) -> float:
        """Where ``value`` of the observation's ``dimension`` lies in the clustering space
        (the raw observation's dimensions are scaled one by one, so the others, 0 here, do
        not matter)."""
        x = np.zeros(self.dim)
        x[dimension] = value
        return float(self.normalise(x)[dimension])

    def physical(self, z: FloatArray) -> FloatArray:
        """The clustering space back to physical units: the observation (the inverse of
        :meth:`normalise`) where it is clustered, then each feature's value."""
        n_raw = self.dim if self.raw else 0
        features = self._feature_low + z[..., n_raw:] * self._feature_range
        if not self.raw:
            return features
        warped = self._low + z[..., :n_raw] * self._range
        k = self._knee
        inner = np.abs(warped) <= 2 * k
        unwarped = np.where(inner, warped / 2, warped - np.sign(warped) * k)
        raw: FloatArray = np.where(self._curved, unwarped, warped)
        return np.concatenate([raw, features], axis=-1) if features.shape[-1] else raw


@njit(cache=True)
def normalise(
    x: FloatArray, raw: bool, scales: FloatArray, features: FloatArray, out: FloatArray
) -> None:
    """:meth:`ObservationSpace.normalise` into ``out``, on its packed ``scales`` and
    ``features``."""
    at, d = 0, x.shape[0]
    if raw:
        for i in range(d):
            value = x[i]
            if scales[0, i] > 0.0:
                value += min(max(value, -scales[1, i]), scales[1, i])
            out[i] = (value - scales[2, i]) / scales[3, i]
        at = d
    for f in range(features.shape[0]):
        value = 0.0
        for i in range(d):
            value += features[f, i] * x[i]
        if features[f, 2 * d] > 0.0:
            divisor = 0.0
            for i in range(d):
                divisor += features[f, d + i] * x[i]
            value /= max(divisor, features[f, 2 * d + 1])
        low, width = features[f, 2 * d + 2], features[f, 2 * d + 3]
        out[at + f] = min(max((value - low) / width, 0.0), 1.0)


@njit(cache=True)
def check(x: FloatArray, limit: float) -> int:
    """0 when every value is finite and within +-limit, 1 when one is not finite, 2 when one
    is beyond the limit."""
    for value in x:
        if not np.isfinite(value):
            return 1
    for value in x:
        if abs(value) > limit:
            return 2
    return 0
