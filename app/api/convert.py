"""Request bodies to service steps, and decision records back to JSON."""

from __future__ import annotations

from typing import Any

import orjson

from app.api.schemas import ReviseRequest
from app.core import Decision
from app.service.registry import Step


def to_json(content: Any) -> bytes:
    """Decision records (and whatever holds them) as JSON: each record as
    :meth:`Decision.to_dict` writes it (plain dicts, which orjson writes several times faster
    than the records' dataclasses)."""
    return orjson.dumps(content, default=_plain, option=orjson.OPT_PASSTHROUGH_DATACLASS)


def _plain(value: Any) -> dict[str, Any]:
    if isinstance(value, Decision):
        return value.to_dict()
    raise TypeError(f"{type(value).__name__} is not JSON")


def to_step(body: ReviseRequest) -> Step:
    return Step(
        body.observation,
        body.action,
        body.stream,
        body.event,
        body.done,
        body.applied_action,
        body.learn,
        body.shadow,
        body.idempotency_key,
    )
