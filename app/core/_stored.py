"""Reading a snapshot's parts with every invariant checked before it is used.

A snapshot may come from anywhere (a file, a ``PUT``): each number and array is read through
these functions, which refuse with :class:`InvalidSnapshot` naming the part at fault, so a
restore either yields a model that can take any step or changes nothing.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from app.core.errors import InvalidSnapshot

# Stored floats beyond this magnitude are refused: their squares (distances, potentials)
# must stay finite.
MAX_STORED = 1e100
# Counters (steps, versions, and every count, which none of them exceeds) stay below this,
# where integers are still exact as floats and no sum of counts overflows int64; at a million
# steps a second a model reaches it in 285 years.
MAX_COUNT = 2**53
# How far a stored distribution's sum may lie from 1 (rounding of the truncated beliefs)
SUM_TOLERANCE = 1e-6


def integer(value: Any, field: str, low: int = 0, high: int | None = None) -> int:
    """An integer in ``[low, high]`` (a bool or a float with a fraction is refused)."""
    if isinstance(value, bool) or not isinstance(value, int | np.integer):
        if not (isinstance(value, float | np.floating) and float(value).is_integer()):
            raise InvalidSnapshot("expected an integer", field=field)
    number = int(value)
    if number < low or (high is not None and number > high):
        bound = f"[{low}, {high}]" if high is not None else f">= {low}"
        raise InvalidSnapshot(f"{number} lies outside {bound}", field=field)
    return number


def boolean(value: Any, field: str) -> bool:
    """A true or false (numbers are refused)."""
    if not isinstance(value, bool | np.bool_):
        raise InvalidSnapshot("expected true or false", field=field)
    return bool(value)


def real(value: Any, field: str, low: float = -MAX_STORED, high: float = MAX_STORED) -> float:
    """A finite number in ``[low, high]``."""
    if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
        raise InvalidSnapshot("expected a number", field=field)
    number = float(value)
    if not low <= number <= high:  # NaN fails too
        raise InvalidSnapshot(f"{number} lies outside [{low:g}, {high:g}]", field=field)
    return number


def floats(
    value: Any,
    field: str,
    shape: Sequence[int] | None = None,
    low: float = -MAX_STORED,
    high: float = MAX_STORED,
) -> npt.NDArray[np.float64]:
    """A float64 array of ``shape`` (any, if None) with every entry finite in ``[low, high]``."""
    array = _numeric(value, field, np.float64, shape)
    if array.size and not (np.isfinite(array).all() and array.min() >= low and array.max() <= high):
        raise InvalidSnapshot(f"entries must be finite and lie in [{low:g}, {high:g}]", field=field)
    return array


def distribution(prob: npt.NDArray[np.float64], field: str) -> None:
    """Refuse probabilities (each in [0, 1] already) whose sum is not 1."""
    if abs(float(prob.sum()) - 1.0) > SUM_TOLERANCE:
        raise InvalidSnapshot(f"probabilities summing to {float(prob.sum()):g}, not 1", field=field)


def ints(
    value: Any,
    field: str,
    shape: Sequence[int] | None = None,
    low: int = 0,
    high: int | None = None,
    dtype: type[np.integer[Any]] = np.int64,
) -> npt.NDArray[Any]:
    """An integer array of ``shape`` with every entry in ``[low, high]``."""
    array = _numeric(value, field, dtype, shape)
    if array.size and (array.min() < low or (high is not None and array.max() > high)):
        bound = f"[{low}, {high}]" if high is not None else f">= {low}"
        raise InvalidSnapshot(f"entries must lie in {bound}", field=field)
    return array


def _numeric(value: Any, field: str, dtype: Any, shape: Sequence[int] | None) -> npt.NDArray[Any]:
    if isinstance(value, np.ndarray):
        if value.dtype.kind not in "biuf":
            raise InvalidSnapshot(f"expected numbers, not dtype {value.dtype}", field=field)
        source = value
    else:
        try:
            source = np.asarray(value)
        except (TypeError, ValueError) as error:
            raise InvalidSnapshot("expected an array of numbers", field=field) from error
        if source.dtype.kind not in "biuf" and source.size:
            raise InvalidSnapshot("expected an array of numbers", field=field)
    want = np.dtype(dtype)
    if want.kind in "iu" and source.size:
        if source.dtype.kind == "f" and not (
            np.isfinite(source).all() and (source == np.round(source)).all()
        ):
            raise InvalidSnapshot("expected integers", field=field)
        limits = np.iinfo(want)
        if source.min() < limits.min or source.max() > limits.max:
            raise InvalidSnapshot("integers out of range", field=field)
    array = source.astype(want)
    if shape is not None and array.shape != tuple(shape):
        if array.size != int(np.prod(shape)):
            raise InvalidSnapshot(
                f"expected shape {list(shape)}, got {list(array.shape)}", field=field
            )
        array = array.reshape(shape)
    return array
