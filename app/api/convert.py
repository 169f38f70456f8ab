"""Request bodies to service steps (decisions go back through :meth:`Decision.to_dict`)."""

from __future__ import annotations

from app.api.schemas import ReviseRequest
from app.service.registry import Step


def to_step(body: ReviseRequest) -> Step:
    return Step(body.observation, body.action, body.stream, body.event, body.done,
                body.applied_action, body.learn, body.shadow)
