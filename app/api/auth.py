"""The bearer token: where a request carries it, and the constant-time check."""

from __future__ import annotations

import hmac
from collections.abc import Mapping


def token_ok(expected: str | None, given: str | None) -> bool:
    """Constant-time comparison; everything passes when the server has no token."""
    if expected is None:
        return True
    return given is not None and hmac.compare_digest(given.encode(), expected.encode())


def given_token(headers: Mapping[str, str], query: Mapping[str, str]) -> str | None:
    """The token from ``Authorization: Bearer`` or, for browsers (WebSocket, EventSource),
    which cannot send headers, the ``token`` query parameter."""
    scheme, _, token = headers.get("authorization", "").partition(" ")
    return token if scheme.lower() == "bearer" else query.get("token")
