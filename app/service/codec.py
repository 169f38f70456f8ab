"""Snapshots in three shapes: exact JSON, NumPy archives, and a readable view for people.

The core's snapshot is plain data plus numpy arrays. ``to_json`` turns arrays into tagged lists
(``{"__array__": dtype, "shape": [...], "data": [...]}``) that round-trip bit for bit (Python
writes float64 with repr), ``to_npz`` stores them natively; both invert exactly.
"""

from __future__ import annotations

import io
import json
from typing import Any

import numpy as np

from app.core import Shield

ARRAY = "__array__"


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


def from_json(value: Any) -> Any:
    """Invert :func:`to_json`."""
    if isinstance(value, dict):
        if ARRAY in value:
            data = np.array(value["data"], dtype=np.dtype(value[ARRAY]))
            return data.reshape(value["shape"])
        return {k: from_json(v) for k, v in value.items()}
    if isinstance(value, list):
        return [from_json(v) for v in value]
    return value


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


def from_npz(blob: bytes) -> dict[str, Any]:
    """Invert :func:`to_npz`."""
    with np.load(io.BytesIO(blob), allow_pickle=False) as archive:
        meta = json.loads(str(archive["meta"]))

        def fill(value: Any) -> Any:
            if isinstance(value, dict):
                if ARRAY in value and len(value) == 1:
                    return archive[value[ARRAY]]
                return {k: fill(v) for k, v in value.items()}
            if isinstance(value, list):
                return [fill(v) for v in value]
            return value

        result: dict[str, Any] = fill(meta)
        return result


def readable(shield: Shield, tpm: str = "sparse", action: int | None = None,
             min_prob: float = 1e-3) -> dict[str, Any]:
    """What a person reads: states in physical units and the matrices (``sparse`` keeps the
    entries of at least ``min_prob``; ``dense`` all of them; ``none`` leaves them out)."""
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
            }
            for i in range(shield.n_states)
        ]
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
            matrices.append({"bin": b, "rows": rows.tolist(), "cols": cols.tolist(),
                             "probs": P[rows, cols].tolist()})
    out["tpm"] = {"format": tpm, "min_prob": min_prob if tpm == "sparse" else None,
                  "matrices": matrices}
    return out
