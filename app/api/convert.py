"""Request bodies to service steps, and decision records back to JSON."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import orjson

from app.api.schemas import ReviseRequest
from app.service.registry import Step


def to_json(content: Any) -> bytes:
    """Decision records (and whatever holds them) as JSON: orjson writes the records'
    dataclasses as :meth:`Decision.to_dict` would, several times faster than the standard
    library; the candidates the risk reviser builds on demand go out as a list."""
    return orjson.dumps(content, default=_listed)


def _listed(value: Any) -> list[Any]:
    if isinstance(value, Sequence):
        return list(value)
    raise TypeError(f"{type(value).__name__} is not JSON")


def to_step(body: ReviseRequest) -> Step:
    return Step(body.observation, body.action, body.stream, body.event, body.done,
                body.applied_action, body.learn, body.shadow)
