"""Sending a step again when its answer did not come, without applying it twice.

A step whose answer is lost (a time-out, a dropped connection, a server killed between applying
the step and answering) may or may not have been applied. Sent again with the same
``idempotency_key``, it is applied once: a server that remembers the key answers with the step's
first decision (docs/api.md, "Sending a step again"). The clients of :mod:`client.shield.remote`
take ``retry=Retry()`` and then give every step a fresh key and send it again on such failures:

    with ShieldClient("http://127.0.0.1:8000", retry=Retry(attempts=10)) as shield:
        decision = shield.revise([14.2, 38.5, 15.0], 0.8, stream="car-1")

By hand, the same thing is a key chosen once per step and reused on every send:

    body = {"observation": [14.2, 38.5, 15.0], "action": 0.8, "idempotency_key": new_key()}
    for attempt in range(10):
        try:
            return shield.revise(**body)  # the same key on every attempt
        except ShieldUnavailable:
            time.sleep(0.1 * 2**attempt)
"""

from __future__ import annotations

import asyncio
import time
import uuid
from collections.abc import Awaitable, Callable, Iterator, Mapping
from dataclasses import dataclass
from typing import Any, TypeVar

T = TypeVar("T")


@dataclass(frozen=True)
class Retry:
    """How often and how patiently a client sends a step again."""

    attempts: int = 5
    """Sends of one step in all, the first included."""
    backoff: float = 0.1  # [s]
    """The wait before the second send; each later wait doubles it."""
    max_backoff: float = 2.0  # [s]
    """The longest wait between two sends."""

    def __post_init__(self) -> None:
        if self.attempts < 1 or self.backoff < 0 or self.max_backoff < 0:
            raise ValueError("attempts must be at least 1 and the waits not negative")

    def waits(self) -> Iterator[float]:
        """The waits between the sends [s]."""
        for attempt in range(self.attempts - 1):
            yield min(self.backoff * 2**attempt, self.max_backoff)


def new_key() -> str:
    """A fresh idempotency key (a random UUID, 32 hex digits)."""
    return uuid.uuid4().hex


def keyed(step: Mapping[str, Any]) -> dict[str, Any]:
    """The step body with an idempotency key: its own, or a fresh one."""
    body = dict(step)
    body.setdefault("idempotency_key", new_key())
    return body


def call_with_retry(
    send: Callable[[], T], retry: Retry, worth_retrying: Callable[[Exception], bool]
) -> T:
    """``send()`` until it answers, at most ``retry.attempts`` times while its error is
    ``worth_retrying``; the last error raised."""
    for wait in retry.waits():
        try:
            return send()
        except Exception as error:
            if not worth_retrying(error):
                raise
        time.sleep(wait)
    return send()


async def call_with_retry_async(
    send: Callable[[], Awaitable[T]], retry: Retry, worth_retrying: Callable[[Exception], bool]
) -> T:
    """:func:`call_with_retry` for a coroutine function."""
    for wait in retry.waits():
        try:
            return await send()
        except Exception as error:
            if not worth_retrying(error):
                raise
        await asyncio.sleep(wait)
    return await send()
