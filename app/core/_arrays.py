"""Growable numpy buffers (states are added one at a time, so arrays grow by doubling) and
the read-only views handed out of them."""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt


def ensure_capacity(
    array: npt.NDArray[Any], needed: int, limit: int, axis: int = 0
) -> npt.NDArray[Any]:
    """Return ``array`` or a zero-padded copy with room for ``needed`` entries along ``axis``.

    Capacity doubles (at least 8) but never passes ``limit`` unless ``needed`` does.
    """
    capacity = array.shape[axis]
    if needed <= capacity:
        return array
    new_capacity = min(max(needed, 2 * capacity, 8), max(limit, needed))
    shape = list(array.shape)
    shape[axis] = new_capacity
    grown = np.zeros(shape, dtype=array.dtype)
    index = [slice(None)] * array.ndim
    index[axis] = slice(0, capacity)
    grown[tuple(index)] = array
    return grown


def read_only(view: npt.NDArray[Any]) -> npt.NDArray[Any]:
    """``view`` marked read-only: the tables' properties hand out views, never copies."""
    view.flags.writeable = False
    return view
