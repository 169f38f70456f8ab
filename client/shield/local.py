"""The shield in-process: the core itself, no network, the same decisions as the service."""

from __future__ import annotations

from typing import Any

from app.core import Decision, Shield, ShieldConfig


class LocalShield:
    """A :class:`~app.core.Shield` behind the :class:`~client.shield.base.StepShield` protocol."""

    def __init__(self, config: ShieldConfig | None = None) -> None:
        self.shield = Shield(config)

    def revise(self, observation: Any, action: float | None, **options: Any) -> Decision:
        return self.shield.step(observation, action, **options)

    def close(self) -> None:
        """Nothing to release."""
