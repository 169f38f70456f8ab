"""What a controller needs from a shield, whatever carries the steps."""

from __future__ import annotations

from typing import Any, Protocol

from app.core import Decision


class StepShield(Protocol):
    """Answers one step of a stream with a decision record (docs/api.md, "One step")."""

    def revise(self, observation: Any, action: float | None, **options: Any) -> Decision:
        """``options`` are the API's: stream, event, done, applied_action, learn, shadow."""
        ...

    def close(self) -> None:
        """Release the connection or the model."""
        ...
