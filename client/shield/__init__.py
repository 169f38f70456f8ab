"""Reach a shield service from Python: over HTTP (sync or async) or a WebSocket session."""

from client.shield.remote import (
    AsyncShieldClient,
    ShieldAPIError,
    ShieldClient,
    ShieldSession,
    ShieldUnavailable,
)

__all__ = [
    "AsyncShieldClient",
    "ShieldAPIError",
    "ShieldClient",
    "ShieldSession",
    "ShieldUnavailable",
]
