"""Typed errors of the e-FSM core.

Every error names the input ``field`` at fault and carries a stable ``code``, so the web layer can
translate it into the contract's error body without inspecting messages. A step that raises one of
these has changed nothing: validation happens before any state is touched.
"""

from __future__ import annotations


class ShieldError(ValueError):
    """Base class: a request or configuration the core refuses."""

    code = "invalid_input"

    def __init__(self, message: str, *, field: str | None = None) -> None:
        super().__init__(message)
        self.message = message
        self.field = field


class InvalidObservation(ShieldError):
    """The observation has the wrong length or holds NaN or infinity."""

    code = "invalid_observation"


class InvalidAction(ShieldError):
    """The action is missing, not finite, or outside the configured range (reject mode)."""

    code = "invalid_action"


class UnknownCriterion(ShieldError):
    """The event names a criterion that the model's configuration does not have."""

    code = "unknown_criterion"


class InvalidConfig(ShieldError):
    """A configuration value is out of its domain; ``field`` is the dotted path."""

    code = "invalid_config"


class InvalidSnapshot(ShieldError):
    """A snapshot is not one this version can restore."""

    code = "invalid_snapshot"
