"""The idempotency key over every transport: a step sent again is answered with its first
decision and not applied again; a key sent with another step is refused (docs/api.md,
"Sending a step again"). ``tests/cluster/test_contract.py`` runs these through a sharded
service."""

from __future__ import annotations

from typing import Any

from fastapi.testclient import TestClient

STEP: dict[str, Any] = {"observation": [10.0, 50.0, 12.0], "action": 0.5}


def version(client: TestClient, name: str = "default") -> int:
    result: int = client.get(f"/models/{name}", params={"tpm": "none"}).json()["model_version"]
    return result


def test_a_step_sent_again_over_http_is_answered_with_its_first_decision(
    client: TestClient,
) -> None:
    first = client.post("/revise", json={**STEP, "idempotency_key": "a"})
    client.post("/revise", json={**STEP, "idempotency_key": "b"})
    again = client.post("/revise", json={**STEP, "idempotency_key": "a"})
    assert first.status_code == again.status_code == 200
    assert again.json() == first.json() and again.json()["model_version"] == 1
    assert version(client) == 2


def test_a_batch_sent_again_is_answered_with_its_first_decisions(client: TestClient) -> None:
    client.post("/models", json={"name": "m"})
    steps = [{**STEP, "action": 0.1 * i, "idempotency_key": f"s{i}"} for i in range(4)]
    first = client.post("/models/m/revise/batch", json={"steps": steps[:3]}).json()
    across = client.post("/revise/batch", json={"steps": [{**s, "model": "m"} for s in steps]})
    assert across.json()["decisions"][:3] == first["decisions"]
    assert across.json()["decisions"][3]["model_version"] == 4
    assert version(client, "m") == 4


def test_a_step_sent_again_over_a_websocket_is_answered_with_its_first_decision(
    client: TestClient,
) -> None:
    with client.websocket_connect("/ws") as ws:
        ws.send_json({**STEP, "idempotency_key": "w"})
        first = ws.receive_json()
    with client.websocket_connect("/ws") as ws:  # a new session, as after a lost one
        ws.send_json({**STEP, "idempotency_key": "w"})
        assert ws.receive_json() == first
        ws.send_json({**STEP, "action": 0.2, "idempotency_key": "w"})
        assert ws.receive_json()["error"]["code"] == "idempotency_key_reused"
    assert client.post("/revise", json={**STEP, "idempotency_key": "w"}).json() == first
    assert version(client) == 1


def test_a_key_sent_with_another_step_is_refused_and_changes_nothing(client: TestClient) -> None:
    client.post("/revise", json={**STEP, "idempotency_key": "k"})
    r = client.post("/revise", json={**STEP, "action": -1.0, "idempotency_key": "k"})
    assert r.status_code == 422
    assert r.json()["error"]["code"] == "idempotency_key_reused"
    assert r.json()["error"]["field"] == "idempotency_key"
    twice = [{**STEP, "model": "default", "idempotency_key": "t"}] * 2
    r = client.post("/revise/batch", json={"steps": twice})
    assert (r.status_code, r.json()["error"]["field"]) == (422, "steps.1.idempotency_key")
    for bad in ("", 7, "x" * 129):
        r = client.post("/revise", json={**STEP, "idempotency_key": bad})
        assert (r.status_code, r.json()["error"]["field"]) == (422, "idempotency_key")
    assert version(client) == 1
