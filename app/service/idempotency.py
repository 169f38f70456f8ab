"""The steps a model remembers by their idempotency key, so that a retried step is answered
with its first decision instead of being applied again.

A client that gets no answer (a time-out, a lost connection, a server killed between applying a
step and answering it) cannot know whether the step was applied; it sends the step again with
the same ``idempotency_key``. Each model remembers the decisions of its last ``size`` keyed
learning steps (a window: the oldest is forgotten first), with a fingerprint of each step, so
that a key sent again with another step is refused rather than answered with a decision that
is not its own. The registry journals each key with its step and the window at each snapshot
(:mod:`app.service.registry`), so the window survives a crash as the model does.
"""

from __future__ import annotations

import hashlib
from collections import OrderedDict
from collections.abc import Iterable, Sequence
from typing import Any

import orjson

from app.core import Decision, ShieldError

Entry = tuple[str, str, str]
"""One remembered step as the journal stores it: key, fingerprint, decision (JSON)."""


class KeyReused(ShieldError):
    """An idempotency key sent again with a step other than the one it first named."""

    code = "idempotency_key_reused"


class TooManyKeys(ShieldError):
    """A request carries more keyed steps of one model than the model remembers."""

    code = "too_large"


def fingerprint(
    observation: Sequence[float],
    action: float | None,
    stream: str,
    event: str | None,
    done: bool,
    applied_action: float | None,
    learn: bool,
    shadow: bool,
) -> str:
    """What makes two steps the same step (8 bytes of BLAKE2b, in hex)."""
    identity = repr(
        (
            [float(v) for v in observation],
            None if action is None else float(action),
            stream,
            event,
            done,
            None if applied_action is None else float(applied_action),
            learn,
            shadow,
        )
    )
    return hashlib.blake2b(identity.encode(), digest_size=8).hexdigest()


class KeyWindow:
    """The decisions of a model's last ``size`` keyed learning steps, by key."""

    def __init__(self, size: int) -> None:
        self.size = size
        self._entries: OrderedDict[str, tuple[str, bytes]] = OrderedDict()

    def __len__(self) -> int:
        return len(self._entries)

    def recall(self, key: str, print_: str, field: str) -> Decision | None:
        """The first decision of the step ``key`` named, None for a key not remembered;
        :class:`KeyReused` (naming ``field``) when ``key`` named another step."""
        entry = self._entries.get(key)
        if entry is None:
            return None
        if entry[0] != print_:
            raise KeyReused(
                f"idempotency key {key!r} was sent with another step; a key names one step",
                field=field,
            )
        return Decision.from_dict(orjson.loads(entry[1]))

    def remember(self, key: str, print_: str, decision: Decision) -> None:
        """Remember a step's decision, forgetting the oldest beyond ``size``."""
        self._entries[key] = (print_, orjson.dumps(decision.to_dict()))
        self._entries.move_to_end(key)
        while len(self._entries) > self.size:
            self._entries.popitem(last=False)

    def check_room(self, keys: int, field: str) -> None:
        """Refuse one request that carries more keyed steps than the window holds: a retry of
        it could not be answered in full."""
        if keys > self.size:
            raise TooManyKeys(
                f"a request carries at most {self.size} steps with an "
                "idempotency key for one model (the server's idempotency_window)",
                field=field,
            )

    def entries(self) -> list[Entry]:
        """The window, oldest first, as the journal stores it."""
        return [(key, p, d.decode()) for key, (p, d) in self._entries.items()]

    def load(self, entries: Iterable[Sequence[Any]]) -> None:
        """Remember journaled entries (:meth:`entries`), in order."""
        for key, print_, decision in entries:
            self._entries[key] = (print_, decision.encode())
            self._entries.move_to_end(key)
        while len(self._entries) > self.size:
            self._entries.popitem(last=False)
