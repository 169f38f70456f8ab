"""Limits an operator can set, so that no caller can exhaust the server (issue #45, finding 5):
streams per model (least recently used forgotten), models per server, states per model."""

from __future__ import annotations

from fastapi.testclient import TestClient

from app.core import LimitsConfig, Shield, ShieldConfig
from app.main import create_app
from app.settings import Settings


def test_streams_beyond_the_limit_forget_the_least_recently_used() -> None:
    shield = Shield(ShieldConfig(limits=LimitsConfig(max_streams=3)))
    for name in ("a", "b", "c"):
        shield.step([10.0, 20.0, 10.0], 0.1, stream=name)
    shield.step([10.0, 21.0, 10.0], 0.1, stream="a")  # 'a' is the most recent now
    shield.step([10.0, 20.0, 10.0], 0.1, stream="d")
    shield.step([10.0, 20.0, 10.0], 0.1, stream="e")
    assert list(shield.streams) == ["a", "d", "e"]
    assert shield.counters.streams_expired == 2
    copy = Shield.from_snapshot(shield.snapshot())
    assert list(copy.streams) == ["a", "d", "e"] and copy.counters.streams_expired == 2
    assert shield.streams["a"].step == 2  # a kept stream keeps its episode


def test_a_server_holds_at_most_max_models_and_max_states_a_model() -> None:
    with TestClient(create_app(Settings(max_models=3, max_states=20_000))) as client:
        for name in ("m1", "m2"):  # 'default' is the first
            assert client.post("/models", json={"name": name}).status_code == 201
        r = client.post("/models", json={"name": "m3"})
        assert r.status_code == 409 and r.json()["error"]["code"] == "too_many_models"
        client.delete("/models/m2")
        big = {"name": "m3", "config": {"limits": {"max_states": 20_001}}}
        r = client.post("/models", json=big)
        assert r.status_code == 422
        assert r.json()["error"] | {"message": ""} == {
            "code": "invalid_config",
            "message": "",
            "field": "config.limits.max_states",
        }
        snapshot = client.get("/models/m1").json()
        snapshot["exact"]["config"]["limits"]["max_states"] = 20_001
        r = client.put("/models/m1", json=snapshot)
        assert r.status_code == 422 and r.json()["error"]["field"] == "config.limits.max_states"
        assert client.post("/models", json={"name": "m3"}).status_code == 201
