"""What models a request of the service's contract is about, read from its path and body: the
ingress routes by it, and a shard checks by it that it still holds them."""

from __future__ import annotations

import json

from app.service.registry import DEFAULT_MODEL


def named(method: str, path: str, body: bytes) -> list[str]:
    """The models an HTTP request is about: its path's (``/models/{name}/...``; ``/revise``
    and ``/model`` mean 'default'), or those its body names when it creates a model or steps
    several. None for the rest, and for a body that cannot be read (any shard answers
    its error)."""
    if method == "POST" and path in ("/models", "/revise/batch"):
        try:
            document = json.loads(body)
        except ValueError:
            return []
        if not isinstance(document, dict):
            return []
        if path == "/models":
            return [document["name"]] if isinstance(document.get("name"), str) else []
        steps = document.get("steps")
        if not isinstance(steps, list):
            return []
        return list(
            dict.fromkeys(
                s["model"] for s in steps if isinstance(s, dict) and isinstance(s.get("model"), str)
            )
        )
    parts = path.strip("/").split("/")
    if parts[0] == "models" and len(parts) >= 2 and parts[1]:
        return [parts[1]]
    if path in ("/revise", "/model"):
        return [DEFAULT_MODEL]
    return []
