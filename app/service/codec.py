"""Snapshots in three shapes: exact JSON, NumPy archives, and a readable view for people.

The core's snapshot is plain data plus numpy arrays. ``to_json`` turns arrays into tagged lists
(``{"__array__": dtype, "shape": [...], "data": [...]}``) that round-trip bit for bit (Python
writes float64 with repr), ``to_npz`` stores them natively; both invert exactly.
"""

from __future__ import annotations

import io
import json
import math
import zipfile
import zlib
from typing import Any

import numpy as np

from app.core import InvalidSnapshot, Shield
from app.core.record import COLUMNS as RECORD_COLUMNS

ARRAY = "__array__"
# The dtypes a snapshot's arrays may have: what the core writes (float64, int64, int32).
DTYPES = frozenset({"<f8", "<i8", "<i4"})
DEFAULT_LIMIT = 256 * 2**20  # [bytes] of arrays in one snapshot


def to_json(value: Any) -> Any:
    """Replace every numpy array or scalar by JSON-able data."""
    if isinstance(value, np.ndarray):
        return {ARRAY: value.dtype.str, "shape": list(value.shape), "data": value.ravel().tolist()}
    if isinstance(value, dict):
        return {str(k): to_json(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [to_json(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def from_json(value: Any, limit: int = DEFAULT_LIMIT) -> Any:
    """Invert :func:`to_json`. Arrays are checked before they are built: a dtype from
    :data:`DTYPES`, a shape that matches the data, at most ``limit`` bytes in all; anything
    else raises :class:`InvalidSnapshot` naming the array."""
    budget = [limit]

    def build(value: Any, path: str) -> Any:
        if isinstance(value, dict):
            if ARRAY in value:
                return _array(value, path, budget)
            return {k: build(v, f"{path}.{k}" if path else str(k)) for k, v in value.items()}
        if isinstance(value, list):
            return [build(v, f"{path}.{i}") for i, v in enumerate(value)]
        return value

    return build(value, "")


def _array(tagged: dict[str, Any], path: str, budget: list[int]) -> np.ndarray:
    dtype, shape, data = tagged.get(ARRAY), tagged.get("shape"), tagged.get("data")
    if dtype not in DTYPES:
        raise InvalidSnapshot(f"array dtype {dtype!r} is not one of {sorted(DTYPES)}", field=path)
    if not (
        isinstance(shape, list)
        and all(isinstance(d, int) and not isinstance(d, bool) and d >= 0 for d in shape)
    ):
        raise InvalidSnapshot("an array's shape is a list of sizes", field=path)
    if not isinstance(data, list) or len(data) != math.prod(shape):
        raise InvalidSnapshot("an array's data must hold as many numbers as its shape", field=path)
    budget[0] -= len(data) * np.dtype(dtype).itemsize
    if budget[0] < 0:
        raise InvalidSnapshot("the snapshot's arrays exceed the size limit", field=path)
    try:
        return np.array(data, dtype=np.dtype(dtype)).reshape(shape)
    except (TypeError, ValueError, OverflowError) as error:
        raise InvalidSnapshot(
            f"an array holds something else than numbers: {error}", field=path
        ) from error


def to_npz(snapshot: dict[str, Any]) -> bytes:
    """A NumPy archive: every array under its path, the rest as JSON in ``meta``."""
    arrays: dict[str, np.ndarray] = {}

    def strip(value: Any, path: str) -> Any:
        if isinstance(value, np.ndarray):
            arrays[path] = value
            return {ARRAY: path}
        if isinstance(value, dict):
            return {k: strip(v, f"{path}/{k}") for k, v in value.items()}
        if isinstance(value, list | tuple):
            return [strip(v, f"{path}/{i}") for i, v in enumerate(value)]
        return value

    members: dict[str, Any] = {"meta": np.array(json.dumps(strip(snapshot, ""))), **arrays}
    buffer = io.BytesIO()
    np.savez_compressed(buffer, **members)
    return buffer.getvalue()


def from_npz(blob: bytes, limit: int = DEFAULT_LIMIT) -> dict[str, Any]:
    """Invert :func:`to_npz`, inflating nothing the format does not name.

    The archive's directory is read first (no member inflated): the sizes it declares must
    stay within ``limit`` in all, and hold ``meta``. Then ``meta`` alone is inflated, and
    every other member must be an array it names: one it does not is refused unread. Each
    array's header must name a dtype from :data:`DTYPES` and exactly as many bytes as its
    member declares, which is all that reading it inflates (zipfile stops at the declared
    size). A damaged archive or anything else raises :class:`InvalidSnapshot`."""
    try:
        with zipfile.ZipFile(io.BytesIO(blob)) as archive:
            infos = archive.infolist()
            names = [info.filename for info in infos]
            if len(set(names)) != len(names):
                raise InvalidSnapshot("the archive names a member twice", field="body")
            if sum(info.file_size for info in infos) > limit:
                raise InvalidSnapshot("the archive inflates beyond the size limit", field="body")
            if META not in names:
                raise InvalidSnapshot("the archive lacks its meta member", field="meta")
            meta = json.loads(str(_read_member(archive, META)))
            named = {f"{path}.npy" for path in _array_paths(meta)}
            for name in names:
                if name != META and name not in named:
                    raise InvalidSnapshot(
                        "a member the snapshot does not name", field=name.removesuffix(".npy")
                    )
            members = {
                name.removesuffix(".npy"): _read_member(archive, name)
                for name in names
                if name != META
            }
    except InvalidSnapshot:
        raise
    except (
        zipfile.BadZipFile,
        zlib.error,
        EOFError,
        OSError,
        ValueError,
        KeyError,
        RecursionError,
        UnicodeDecodeError,
        NotImplementedError,
    ) as error:
        raise InvalidSnapshot(f"unreadable archive: {error}", field="body") from error

    def fill(value: Any) -> Any:
        if isinstance(value, dict):
            if ARRAY in value and len(value) == 1:
                if value[ARRAY] not in members:
                    raise InvalidSnapshot("the archive lacks an array", field=str(value[ARRAY]))
                return members[value[ARRAY]]
            return {k: fill(v) for k, v in value.items()}
        if isinstance(value, list):
            return [fill(v) for v in value]
        return value

    result: dict[str, Any] = fill(meta)
    return result


META = "meta.npy"


def _array_paths(meta: Any) -> list[str]:
    """The members ``meta`` names: every ``{"__array__": path}`` in it."""
    if isinstance(meta, dict):
        if ARRAY in meta and len(meta) == 1:
            return [str(meta[ARRAY])]
        return [p for v in meta.values() for p in _array_paths(v)]
    if isinstance(meta, list):
        return [p for v in meta for p in _array_paths(v)]
    return []


def _read_member(archive: zipfile.ZipFile, name: str) -> np.ndarray:
    """One array, its header checked before its data is inflated: a dtype allowed (text for
    ``meta`` alone) and a size equal to what the member declares."""
    key = name.removesuffix(".npy")
    declared = archive.getinfo(name).file_size
    with archive.open(name) as member:
        version = np.lib.format.read_magic(member)
        if version == (1, 0):
            shape, fortran, dtype = np.lib.format.read_array_header_1_0(member)
        else:
            shape, fortran, dtype = np.lib.format.read_array_header_2_0(member)
        allowed = dtype.kind == "U" if name == META else dtype.str in DTYPES
        if not allowed:
            raise InvalidSnapshot(f"array dtype {dtype.str!r} is not allowed", field=key)
        size = math.prod(shape) * dtype.itemsize
        if member.tell() + size != declared:
            raise InvalidSnapshot("an array's header and its member's size disagree", field=key)
        data = bytearray(size)  # the only copy: the array is a writeable view of it
        if member.readinto(data) != size:  # type: ignore[attr-defined]  # (a ZipExtFile)
            raise InvalidSnapshot("an array's data ends early", field=key)
    return np.frombuffer(data, dtype=dtype).reshape(shape, order="F" if fortran else "C")


def readable(
    shield: Shield, tpm: str = "sparse", action: int | None = None, min_prob: float = 1e-3
) -> dict[str, Any]:
    """What a person reads: states (with the shield's own record there, and whether it backs
    off there), the reach's failure points in physical units, the shield's trial of itself
    (episodes and failed episodes, shielded and audited), and the
    matrices (``sparse`` keeps the entries of at least ``min_prob``; ``dense`` all of them;
    ``none`` leaves them out)."""
    states = shield.states()
    criteria = [c.name for c in shield.config.criteria]
    out: dict[str, Any] = {
        "states": [
            {
                "index": i,
                "centre": [float(v) for v in states["centre"][i]],
                "spread": float(states["spread"][i]),
                "flag": states["flag"][i],
                "visits": int(states["visits"][i]),
                "entries": int(states["entries"][i]),
                "failures": dict(zip(criteria, states["failures"][i].tolist(), strict=True)),
                "record": dict(zip(RECORD_COLUMNS, states["record"][i].tolist(), strict=True)),
                "backed_off": bool(states["backed_off"][i]),
            }
            for i in range(shield.n_states)
        ],
        "failure_points": {
            name: points.tolist() for name, points in shield.failure_points().items()
        },
        "trial": shield.reviser.trial_view(),
    }
    if tpm == "none":
        return out
    bins = range(shield.config.action.n_bins) if action is None else [action]
    matrices = []
    for b in bins:
        P = shield.transitions.matrix(b)
        if tpm == "dense":
            matrices.append({"bin": b, "dense": P.tolist()})
        else:
            rows, cols = np.nonzero(P >= min_prob)
            matrices.append(
                {
                    "bin": b,
                    "rows": rows.tolist(),
                    "cols": cols.tolist(),
                    "probs": P[rows, cols].tolist(),
                }
            )
    out["tpm"] = {
        "format": tpm,
        "min_prob": min_prob if tpm == "sparse" else None,
        "matrices": matrices,
    }
    return out
