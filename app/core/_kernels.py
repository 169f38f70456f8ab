"""Arithmetic shared by the compiled kernels: sums in one fixed order, elementwise exp and log,
weighted least squares.

The core's per-step path runs as numba kernels (``@njit(cache=True)``) on preallocated arrays.
Its numbers must not depend on the CPU (docs/algorithm.md, "Determinism"): every sum is written
out here in one explicit order, never left to a library whose order follows the vector width
(BLAS, a SIMD reduction), and every ``exp``/``log`` of an array goes through the platform's libm
one element at a time (:func:`exp`, :func:`log`), never through numpy's SIMD loops, whose
results differ in the last bit between CPUs (AVX-512 has its own) and with an array's alignment.
The tests keep a plain-Python reading of each beside it.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from numba import njit

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

NEG_INF = -math.inf


@njit(cache=True)
def pairwise_sum(x: FloatArray, n: int) -> float:
    """The sum of ``x[:n]`` in one fixed pairwise order: blocks of at most 128 summed by
    :func:`_block`, longer runs halved (to a multiple of 8) and the halves added, walked here
    with a stack instead of recursion. This is the order numpy's source fixes for ``np.sum`` of
    a contiguous float64 vector (as accurate, O(log n) error growth), written out so that it
    holds whatever the library or the CPU."""
    if n <= 128:
        return _block(x, 0, n)
    starts = np.empty(64, dtype=np.int64)
    lengths = np.empty(64, dtype=np.int64)
    phase = np.zeros(64, dtype=np.int64)  # 0: new, 1: left half pending, 2: right pending
    lefts = np.empty(64)
    depth, result = 0, 0.0
    starts[0], lengths[0] = 0, n
    while depth >= 0:
        start, length = starts[depth], lengths[depth]
        if length <= 128:
            result = _block(x, start, length)
            depth -= 1
            continue
        half = length // 2
        half -= half % 8
        if phase[depth] == 2:
            result = lefts[depth] + result
            depth -= 1
            continue
        if phase[depth] == 1:
            lefts[depth] = result
            start, half = start + half, length - half
        phase[depth] += 1
        depth += 1
        starts[depth], lengths[depth], phase[depth] = start, half, 0
    return result


@njit(cache=True)
def _block(x: FloatArray, start: int, n: int) -> float:
    """At most 128 numbers: one by one below 8, else eight accumulators, then the rest."""
    if n < 8:
        total: float = -0.0
        for i in range(n):
            total += x[start + i]
        return total
    r0, r1, r2, r3 = x[start], x[start + 1], x[start + 2], x[start + 3]
    r4, r5, r6, r7 = x[start + 4], x[start + 5], x[start + 6], x[start + 7]
    i = 8
    while i < n - n % 8:
        r0 += x[start + i]
        r1 += x[start + i + 1]
        r2 += x[start + i + 2]
        r3 += x[start + i + 3]
        r4 += x[start + i + 4]
        r5 += x[start + i + 5]
        r6 += x[start + i + 6]
        r7 += x[start + i + 7]
        i += 8
    total = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        total += x[start + i]
        i += 1
    return total


@njit(cache=True)
def logaddexp(x: float, y: float) -> float:
    """``log(exp(x) + exp(y))`` without overflow, in numpy's formula (``np.logaddexp``), on
    libm's ``exp`` and ``log1p``."""
    if x == y:
        return x + math.log(2.0)
    d = x - y
    if d > 0:
        return x + math.log1p(math.exp(-d))
    if d <= 0:
        return y + math.log1p(math.exp(d))
    return x + y


@njit(cache=True)
def exp(x: FloatArray) -> FloatArray:
    """``exp`` of every element, one libm call each (see the module's docstring)."""
    out = np.empty_like(x)
    for at in np.ndindex(x.shape):
        out[at] = math.exp(x[at])
    return out


@njit(cache=True)
def log(x: FloatArray) -> FloatArray:
    """``log`` of every element (``-inf`` at 0), one libm call each."""
    out = np.empty_like(x)
    for at in np.ndindex(x.shape):
        out[at] = math.log(x[at]) if x[at] > 0.0 else (NEG_INF if x[at] == 0.0 else math.nan)
    return out


@njit(cache=True)
def weighted_rls(
    weights: FloatArray,
    cov: FloatArray,
    index: IntArray,
    prob: FloatArray,
    phi: FloatArray,
    targets: FloatArray,
    min_weight: float,
) -> None:
    """One sample ``(phi, targets)`` into the linear models ``weights[i]`` (outputs x
    features) of the states ``index``: weighted recursive least squares, each with weight
    ``prob`` (the state's membership), every output sharing the state's covariance
    ``cov[i]``. Entries of weight below ``min_weight`` (padding among them) change nothing."""
    m = phi.shape[0]
    gain = np.empty(m)
    for t in range(index.shape[0]):
        i, weight = index[t], prob[t]
        if weight < min_weight:
            continue
        denominator = 1.0 / weight
        for r in range(m):
            total = 0.0
            for s in range(m):
                total += cov[i, r, s] * phi[s]
            gain[r] = total
            denominator += phi[r] * total
        for c in range(targets.shape[0]):
            error = targets[c]
            for r in range(m):
                error -= weights[i, c, r] * phi[r]
            for r in range(m):
                weights[i, c, r] += gain[r] * error / denominator
        for r in range(m):
            for s in range(m):
                cov[i, r, s] -= gain[r] * gain[s] / denominator
