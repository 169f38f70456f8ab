"""Continuous-to-discrete action encoding (docs/algorithm.md).

Bins are 0-based here: bin 0 is the hardest braking interval [low, low + delta), bin q - 1 the
strongest acceleration (closed on the right). The paper numbers them 1..q.
"""

from __future__ import annotations

import math

from app.core.config import ActionSpec


def encode(action: float, spec: ActionSpec) -> int:
    """The bin r of an action: ``min(q, floor((clip(a) - a_min) / delta) + 1)``, 0-based."""
    clipped = min(max(action, spec.low), spec.high)
    # A tiny tolerance keeps bin edges such as -1.8 = -2 + 1 * 0.2 in the upper bin.
    index = math.floor((clipped - spec.low) / spec.step + 1e-9)
    return min(spec.n_bins - 1, index)


def decode(bin_index: int, spec: ActionSpec) -> float:
    """The midpoint of a bin: ``a_min + (r - 0.5) * delta`` with 1-based r.

    Bin -1 (below the range) is reachable only by the literal Alg. 2 (A6) and decodes to
    ``a_min - delta / 2``, which the caller clips.
    """
    return spec.low + (bin_index + 0.5) * spec.step
