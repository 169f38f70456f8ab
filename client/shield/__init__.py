"""Reach a shield from Python: in-process, over HTTP (sync or async, single or batch), or a
WebSocket session; all answer ``revise(observation, action, **options) -> Decision``."""

from client.shield.base import StepShield
from client.shield.local import LocalShield
from client.shield.remote import (
    AsyncShieldClient,
    BatchShield,
    ShieldAPIError,
    ShieldClient,
    ShieldSession,
    ShieldUnavailable,
)

__all__ = [
    "AsyncShieldClient",
    "BatchShield",
    "LocalShield",
    "StepShield",
    "ShieldAPIError",
    "ShieldClient",
    "ShieldSession",
    "ShieldUnavailable",
]
