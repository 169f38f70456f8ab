"""Bodies to service calls and decisions to JSON, by hand: this is the per-step path."""

from __future__ import annotations

from typing import Any

from app.api.schemas import ReviseRequest
from app.core import Decision
from app.service.registry import Step


def to_step(body: ReviseRequest) -> Step:
    return Step(body.observation, body.action, body.stream, body.event, body.done,
                body.applied_action, body.learn, body.shadow)


def decision_json(d: Decision) -> dict[str, Any]:
    return {
        "action": d.action, "proposed": d.proposed, "revised": d.revised, "reason": d.reason,
        "verdict": d.verdict, "risk": d.risk, "threshold": d.threshold,
        "candidates": [{"action": c.action, "bin": c.bin, "verdict": c.verdict}
                       for c in d.candidates],
        "state": d.state, "n_states": d.n_states, "new_state": d.new_state,
        "episode": d.episode, "step": d.step, "model_version": d.model_version,
        "stream": d.stream, "shadow": d.shadow, "suggested": d.suggested,
    }
