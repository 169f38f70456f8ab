"""Reach a shield from Python: in-process, over HTTP (sync or async, single or batch), or a
WebSocket session; all answer ``revise(observation, action, **options) -> Decision``, and the
remote ones send a step again without applying it twice with ``retry=Retry()``. Or put
it in front of a Gymnasium environment: :class:`ShieldWrapper`, or of a vectorised one with one
model for every copy: :class:`ShieldVectorWrapper`."""

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
from client.shield.retry import Retry, new_key
from client.shield.spaces import (
    SpaceMismatch,
    check_config,
    config_for,
    sample_observations,
)
from client.shield.vector import ShieldVectorWrapper
from client.shield.wrapper import NoFailureReported, ShieldWrapper

__all__ = [
    "AsyncShieldClient",
    "BatchShield",
    "LocalShield",
    "Retry",
    "NoFailureReported",
    "StepShield",
    "ShieldAPIError",
    "ShieldClient",
    "ShieldSession",
    "ShieldUnavailable",
    "ShieldVectorWrapper",
    "ShieldWrapper",
    "SpaceMismatch",
    "check_config",
    "config_for",
    "new_key",
    "sample_observations",
]
