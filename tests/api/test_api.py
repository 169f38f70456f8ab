"""The HTTP and WebSocket contract of docs/api.md, in process."""

from __future__ import annotations

import json
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest
from fastapi.testclient import TestClient

import app
from app.core import compiled
from app.main import create_app
from app.service import codec
from app.settings import Settings

STEP = {"observation": [14.2, 38.5, 15.0], "action": 0.8}


def episode(
    c: TestClient, path: str = "/revise", stream: str = "0", n: int = 6, crash: bool = True
) -> list[dict[str, Any]]:
    out = []
    for t in range(n):
        body = {"observation": [10.0 + t, 12.0 - 2 * t, 9.0], "action": 0.5, "stream": stream}
        out.append(c.post(path, json=body).json())
    end = {
        "observation": [16.0, 0.0, 9.0],
        "action": None,
        "stream": stream,
        "done": True,
        "event": "collision" if crash else None,
    }
    out.append(c.post(path, json=end).json())
    return out


def exact(c: TestClient, name: str = "default") -> Any:
    return c.get(f"/models/{name}", params={"tpm": "none"}).json()["exact"]


def test_revise_returns_the_decision_record(client: TestClient) -> None:
    r = client.post("/revise", json=STEP)
    assert r.status_code == 200
    d = r.json()
    assert set(d) == {
        "action",
        "proposed",
        "revised",
        "reason",
        "verdict",
        "risk",
        "threshold",
        "candidates",
        "state",
        "n_states",
        "new_state",
        "episode",
        "step",
        "model_version",
        "stream",
        "shadow",
        "suggested",
    }
    assert (d["action"], d["reason"]) == (0.8, "cold_start")
    assert (d["n_states"], d["model_version"]) == (1, 1)


def test_episodes_flags_and_counters_through_the_api(client: TestClient) -> None:
    decisions = episode(client)
    assert decisions[-1]["reason"] == "done" and decisions[-1]["action"] is None
    assert decisions[-1]["episode"] == 1
    snap = client.get("/model").json()
    assert snap["episodes"] == 1 and snap["steps"] == 7
    assert "collision" in [s["flag"] for s in snap["states"]]
    assert sum(s["failures"]["collision"] for s in snap["states"]) == 1
    # the reach keeps where the collision was seen, in physical units
    assert snap["failure_points"]["large_distance"] == []
    assert np.allclose(snap["failure_points"]["collision"], [[16.0, 0.0, 9.0]])
    assert sum(s["visits"] for s in snap["states"]) == 7
    visited = [d["state"] for d in decisions]
    entered = 1 + sum(a != b for a, b in zip(visited, visited[1:], strict=False))
    assert sum(s["entries"] for s in snap["states"]) == entered
    # the shield's own record: the episode's six decided steps, passed, one failure after them
    records = [s["record"] for s in snap["states"]]
    assert sum(r["passed"] for r in records) == 6 and sum(r["revised"] for r in records) == 0
    assert sum(r["passed_failed"] for r in records) == 6
    assert not any(s["backed_off"] for s in snap["states"])
    # the trial of itself: the first episode came before any failure was learned, uncounted;
    # the second is drawn into an arm and counted there when it ends
    empty = {"episodes": 0, "failed": 0}
    assert snap["trial"] == {"shielded": empty, "audited": empty}
    episode(client, crash=False)
    trial = client.get("/model", params={"tpm": "none"}).json()["trial"]
    assert sum(arm["episodes"] for arm in trial.values()) == 1
    assert sum(arm["failed"] for arm in trial.values()) == 0


def test_models_lifecycle(client: TestClient) -> None:
    r = client.post("/models", json={"name": "run-1", "config": {"reviser": {"seed": 3}}})
    assert r.status_code == 201 and r.json()["name"] == "run-1"
    assert client.post("/models", json={"name": "run-1"}).status_code == 409
    assert client.post("/models/run-1/revise", json=STEP).json()["model_version"] == 1
    assert [m["name"] for m in client.get("/models").json()["models"]] == ["default", "run-1"]
    assert client.post("/models/run-1/reset").json()["n_states"] == 0
    assert client.delete("/models/run-1").status_code == 204
    assert client.get("/models/run-1").status_code == 404


def test_snapshot_views(client: TestClient) -> None:
    episode(client)
    sparse = client.get("/model").json()
    assert sparse["tpm"]["format"] == "sparse" and len(sparse["tpm"]["matrices"]) == 20
    n = sparse["n_states"]
    dense = client.get("/model", params={"tpm": "dense", "action": 12}).json()
    [matrix] = dense["tpm"]["matrices"]
    assert matrix["bin"] == 12 and np.allclose(np.sum(matrix["dense"], axis=1), 1.0)
    assert np.array(matrix["dense"]).shape == (n, n)
    assert "tpm" not in client.get("/model", params={"tpm": "none"}).json()
    assert "exact" not in client.get("/model", params={"exact": False}).json()


@pytest.mark.parametrize(
    ("params", "field"), [({"tpm": "bogus"}, "tpm"), ({"action": "twelve"}, "action")]
)
def test_a_bad_query_parameter_is_named_as_such(
    client: TestClient, params: dict[str, str], field: str
) -> None:
    r = client.get("/model", params=params)
    assert r.status_code == 422
    assert r.json()["error"] | {"message": ""} == {
        "code": "invalid_query",
        "message": "",
        "field": field,
    }


def test_snapshot_put_restores_a_model_that_decides_alike(client: TestClient) -> None:
    client.post(
        "/models", json={"name": "a", "config": {"reviser": {"activate_after_episodes": 1}}}
    )
    for _ in range(3):
        episode(client, "/models/a/revise")
    snap = client.get("/models/a").json()
    assert client.put("/models/b", json=snap).status_code == 200
    npz = client.get("/models/a", headers={"accept": "application/x-npz"}).content
    assert (
        client.put(
            "/models/c", content=npz, headers={"content-type": "application/x-npz"}
        ).status_code
        == 200
    )
    runs = [episode(client, f"/models/{m}/revise") for m in ("a", "b", "c")]
    assert runs[0] == runs[1] == runs[2]
    # the reviser decided: it revised, or it would have in an episode it audits
    assert any(d["reason"] in ("revised_safety", "audit") for d in runs[0])


def test_the_risk_reviser_through_the_api(client: TestClient) -> None:
    config = {
        "reviser": {"method": "risk", "activate_after_episodes": 1},
        "risk": {"horizon": 4},
        "observation": {
            "features": [{"name": "closing", "weights": [1, 0, -1], "low": -10, "high": 10}]
        },
    }
    assert client.post("/models", json={"name": "r", "config": config}).status_code == 201
    for _ in range(3):
        episode(client, "/models/r/revise")
    summary = client.get("/models/r").json()
    assert summary["exact"]["config"]["risk"]["horizon"] == 4
    assert client.put("/models/r2", json=summary).status_code == 200
    revised: list[dict[str, Any]] = []
    for _ in range(10):  # until an episode the shield acts in (it audits some: app.core.trial)
        runs = [episode(client, f"/models/{m}/revise") for m in ("r", "r2")]
        assert runs[0] == runs[1]
        revised = [d for d in runs[0] if d["revised"]]
        if revised:
            break
    assert revised and revised[0]["reason"] == "revised_safety"
    assert revised[0]["risk"]["collision"] > 0.0
    assert all(set(c["risk"]) == {"collision", "large_distance"} for c in revised[0]["candidates"])


def test_npz_download_matches_the_core_snapshot(client: TestClient) -> None:
    episode(client)
    blob = client.get("/model", params={"format": "npz"}).content
    restored = codec.from_npz(blob)
    assert restored["counters"]["steps"] == 7


def test_batch_and_batch_across_models(client: TestClient) -> None:
    client.post("/models", json={"name": "r1"})
    client.post("/models", json={"name": "r2"})
    steps = [{**STEP, "stream": "s"}, {**STEP, "stream": "s"}]
    r = client.post("/models/r1/revise/batch", json={"steps": steps})
    assert [d["step"] for d in r.json()["decisions"]] == [0, 1]
    across = [{**STEP, "model": "r1"}, {**STEP, "model": "r2"}, {**STEP, "model": "r2"}]
    r = client.post("/revise/batch", json={"steps": across})
    assert [d["model_version"] for d in r.json()["decisions"]] == [3, 1, 2]


BAD = [
    (
        "/revise",
        {"observation": [1.0, 2.0], "action": 0.0},
        422,
        "invalid_observation",
        "observation",
    ),
    (
        "/revise",
        '{"observation": [1.0, NaN, 2.0], "action": 0.0}',
        422,
        "invalid_body",
        "observation.1",
    ),
    (
        "/revise",
        '{"observation": [1.0, Infinity, 2.0], "action": 0.0}',
        422,
        "invalid_body",
        "observation.1",
    ),
    ("/revise", {"observation": "fast", "action": 0.0}, 422, "invalid_body", "observation"),
    (
        "/revise",
        {"observation": [1.0, 1e160, 2.0], "action": 0.0},
        422,
        "invalid_observation",
        "observation",
    ),
    (
        "/revise",
        {"observation": [1.0, 1e160, 2.0], "action": 0.0, "learn": False},
        422,
        "invalid_observation",
        "observation",
    ),
    (
        "/models/default/revise/batch",
        {"steps": [STEP, STEP, {**STEP, "observation": [1.0, 2.0, 1e308]}]},
        422,
        "invalid_observation",
        "steps.2.observation",
    ),
    ("/revise", {"observation": [1.0, 2.0, 3.0], "action": "0.5"}, 422, "invalid_body", "action"),
    (
        "/revise",
        {"observation": [1.0, 2.0, 3.0], "action": 0.0, "done": "yes"},
        422,
        "invalid_body",
        "done",
    ),
    (
        "/revise",
        {"observation": [1.0, 2.0, 3.0], "action": 0.0, "event": "meteor"},
        422,
        "unknown_criterion",
        "event",
    ),
    ("/revise", {"observation": [1.0, 2.0, 3.0]}, 422, "invalid_action", "action"),
    (
        "/revise",
        {"observation": [1.0, 2.0, 3.0], "action": 0.0, "colour": "red"},
        422,
        "invalid_body",
        "colour",
    ),
    ("/revise", "{not json", 422, "invalid_json", None),
    ("/models/ghost/revise", STEP, 404, "unknown_model", "name"),
    ("/models/BAD!/revise", STEP, 422, "invalid_name", "name"),
    ("/models", {"name": "Bad!"}, 422, "invalid_name", "name"),
    ("/revise/batch", {"steps": [{**STEP, "model": "a/b"}]}, 422, "invalid_name", "steps.0.model"),
    (
        "/models/default/revise/batch",
        {"steps": [STEP, {**STEP, "observation": [1.0]}, STEP]},
        422,
        "invalid_observation",
        "steps.1.observation",
    ),
    (
        "/models/default/revise/batch",
        {"steps": [{**STEP, "observation": [1.0]}]},
        422,
        "invalid_observation",
        "steps.0.observation",
    ),
    (
        "/revise/batch",
        {"steps": [{**STEP, "model": "default"}, {**STEP, "model": "ghost"}]},
        404,
        "unknown_model",
        "name",
    ),
]


@pytest.mark.parametrize(("path", "body", "status", "code", "field"), BAD)
def test_bad_requests_get_an_error_body_and_change_nothing(
    client: TestClient, path: str, body: Any, status: int, code: str, field: str | None
) -> None:
    episode(client, n=3)
    before = exact(client)
    if isinstance(body, str):
        r = client.post(path, content=body, headers={"content-type": "application/json"})
    else:
        r = client.post(path, json=body)
    assert r.status_code == status, r.text
    assert r.json()["error"]["code"] == code
    assert r.json()["error"]["field"] == field
    assert "Traceback" not in r.text
    assert exact(client) == before


def test_bad_configuration_names_the_field(client: TestClient) -> None:
    r = client.post("/models", json={"name": "x", "config": {"clustering": {"rho": 2}}})
    assert r.status_code == 422 and r.json()["error"]["field"] == "config.clustering.rho"
    r = client.post("/models", json={"name": "x", "config": {"reviser": {"nois": "std"}}})
    assert r.json()["error"]["field"] == "config.reviser.nois"
    bound: dict[str, Any] = {
        "name": "collision",
        "direction": "decrease",
        "bound": {"observation": "gap", "below": 0},
    }
    r = client.post("/models", json={"name": "x", "config": {"criteria": [bound]}})
    assert r.status_code == 422
    assert r.json()["error"]["field"] == "config.criteria.0.bound.observation"
    assert client.get("/models/x").status_code == 404
    bound["bound"]["observation"] = "headway"
    r = client.post("/models", json={"name": "x", "config": {"criteria": [bound]}})
    assert r.status_code in (200, 201)
    assert client.get("/models/x").json()["config"]["criteria"][0]["bound"] == {
        "observation": "headway",
        "below": 0.0,
        "above": None,
    }


@pytest.fixture
def strict_client() -> Iterator[TestClient]:
    settings = Settings(token="s3cret", max_body_bytes=4096, max_batch=3)
    with TestClient(create_app(settings)) as c:
        yield c


def test_token_is_required_everywhere_but_health(strict_client: TestClient) -> None:
    c = strict_client
    assert c.get("/healthz").json() == {
        "status": "ok",
        "version": app.__version__,
        "core": compiled.fingerprint()[:12],
    }
    assert c.get("/readyz").status_code == 200
    for method, path in [
        ("post", "/revise"),
        ("post", "/models/default/revise"),
        ("get", "/models"),
        ("get", "/model"),
        ("get", "/metrics"),
        ("get", "/models/default/history"),
        ("post", "/models/default/reset"),
        ("batch", "/revise/batch"),
        ("batch", "/models/default/revise/batch"),
    ]:
        if method == "batch":
            r = c.post(path, json={"steps": [{**STEP, "model": "default"}]})
        else:
            r = getattr(c, method)(path, json=STEP) if method == "post" else c.get(path)
        assert r.status_code == 401, path
        assert r.json()["error"]["code"] == "unauthorized"
    wrong = {"Authorization": "Bearer nope"}
    assert c.post("/revise", json=STEP, headers=wrong).status_code == 401
    good = {"Authorization": "Bearer s3cret"}
    assert c.post("/revise", json=STEP, headers=good).status_code == 200
    assert c.get("/model", headers=good).json()["steps"] == 1


def test_body_and_batch_limits(strict_client: TestClient) -> None:
    good = {"Authorization": "Bearer s3cret"}
    big = {"steps": [STEP] * 200}
    r = strict_client.post("/models/default/revise/batch", json=big, headers=good)
    assert r.status_code == 413 and r.json()["error"]["code"] == "too_large"
    r = strict_client.post("/models/default/revise/batch", json={"steps": [STEP] * 4}, headers=good)
    assert r.status_code == 413 and r.json()["error"]["field"] == "steps"
    assert strict_client.get("/model", headers=good).json()["steps"] == 0


def test_websocket_steps_and_errors_keep_the_connection(client: TestClient) -> None:
    with client.websocket_connect("/ws") as ws:
        ws.send_text(json.dumps(STEP))
        first = ws.receive_json()
        ws.send_text("{broken")
        assert ws.receive_json()["error"]["code"] == "invalid_json"
        ws.send_text('{"observation": [1, NaN, 2], "action": 0}')
        nan = ws.receive_json()["error"]
        assert (nan["code"], nan["field"]) == ("invalid_body", "observation.1")
        ws.send_text(json.dumps({"observation": [1.0], "action": 0.0}))
        assert ws.receive_json()["error"] == {
            "code": "invalid_observation",
            "field": "observation",
            "message": ws_msg(1),
        }
        ws.send_bytes(b"\x00")
        assert ws.receive_json()["error"]["code"] == "unsupported_frame"
        ws.send_text(json.dumps(STEP))
        second = ws.receive_json()
    assert (first["model_version"], second["model_version"]) == (1, 2)


def test_without_the_token_a_bad_request_is_unauthorized_before_it_is_invalid(
    strict_client: TestClient,
) -> None:
    from starlette.websockets import WebSocketDisconnect

    bad = [
        ("/revise", {"observation": "x", "action": 0}),
        ("/models/BAD!/revise", STEP),
        ("/models/default/revise/batch", {"steps": "x"}),
        ("/models", {"name": "Bad!"}),
    ]
    for path, body in bad:
        for headers in ({}, {"Authorization": "Bearer wrong"}):
            r = strict_client.post(path, json=body, headers=headers)
            assert (r.status_code, r.json()["error"]["code"]) == (401, "unauthorized"), path
        r = strict_client.post(path, json=body, headers={"Authorization": "Bearer s3cret"})
        assert r.status_code == 422, path
    with pytest.raises(WebSocketDisconnect) as closed:
        with strict_client.websocket_connect("/models/BAD!/ws") as ws:
            ws.receive_text()
    assert (closed.value.code, closed.value.reason) == (1008, "missing or wrong bearer token")
    with strict_client.websocket_connect("/models/BAD!/ws?token=s3cret") as ws:
        assert ws.receive_json()["error"]["code"] == "invalid_name"


def test_a_websocket_to_a_bad_model_name_gets_the_error_frame_of_an_unknown_one(
    client: TestClient,
) -> None:
    from starlette.websockets import WebSocketDisconnect

    for path, code in (("/models/ghost/ws", "unknown_model"), ("/models/BAD!/ws", "invalid_name")):
        with client.websocket_connect(path) as ws:
            error = ws.receive_json()["error"]
            assert (error["code"], error["field"]) == (code, "name")
            with pytest.raises(WebSocketDisconnect) as closed:
                ws.receive_text()
            assert closed.value.code == 1008


def ws_msg(n: int) -> str:
    return f"observation must hold 3 numbers, got shape [{n}]"


def test_websocket_needs_the_token(strict_client: TestClient) -> None:
    from starlette.websockets import WebSocketDisconnect

    with pytest.raises(WebSocketDisconnect):
        with strict_client.websocket_connect("/ws") as ws:
            ws.receive_json()
    with strict_client.websocket_connect("/ws?token=s3cret") as ws:
        ws.send_text(json.dumps(STEP))
        assert ws.receive_json()["model_version"] == 1


def test_a_websocket_frame_over_the_body_limit_is_refused_and_the_stream_goes_on(
    strict_client: TestClient,
) -> None:
    with strict_client.websocket_connect("/ws?token=s3cret") as ws:
        padded = json.dumps(STEP)[:-1] + ', "stream": "' + "é" * 2100 + '"}'  # 4 KiB in UTF-8
        ws.send_text(padded)
        assert ws.receive_json()["error"] == {
            "code": "too_large",
            "field": None,
            "message": "frame over 4096 bytes",
        }
        ws.send_text(json.dumps(STEP))
        assert ws.receive_json()["model_version"] == 1


def test_metrics_count_requests_decisions_and_states(client: TestClient) -> None:
    episode(client)
    client.post("/models/ghost/revise", json=STEP)
    text = client.get("/metrics").text
    assert 'efsm_http_requests_total{method="POST",route="/revise",status="200"} 7.0' in text
    assert 'route="/models/{name}/revise",status="404"' in text
    assert 'efsm_decisions_total{model="default",reason="done"} 1.0' in text
    assert 'efsm_states{model="default"}' in text
    assert 'efsm_episodes_total{model="default"} 1.0' in text


def decisions_counted(c: TestClient, model: str = "default") -> float:
    """The model's decisions on /metrics, summed over reasons (and shards, if any)."""
    return sum(
        float(line.rsplit(" ", 1)[1])
        for line in c.get("/metrics").text.splitlines()
        if line.startswith("efsm_decisions_total{") and f'model="{model}"' in line
    )


def test_metrics_count_every_decision_once_and_refused_steps_not(client: TestClient) -> None:
    client.post("/revise", json=STEP)
    assert (
        client.post("/models/default/revise/batch", json={"steps": [STEP, STEP]}).status_code == 200
    )
    with client.websocket_connect("/ws") as ws:
        ws.send_text(json.dumps(STEP))
        ws.receive_json()
    assert decisions_counted(client) == 4
    bad = {"observation": [1.0, 2.0], "action": 0.5}
    assert (
        client.post("/models/default/revise/batch", json={"steps": [STEP, bad]}).status_code == 422
    )
    assert client.post("/revise", json=bad).status_code == 422
    assert decisions_counted(client) == 4


def test_openapi_documents_every_request_field(client: TestClient) -> None:
    schema = client.get("/openapi.json").json()
    request = schema["components"]["schemas"]["ReviseRequest"]
    for name, field in request["properties"].items():
        assert field.get("description"), name
    assert request.get("examples")
    assert "/models/{name}/revise/batch" in schema["paths"]
    [(name, scheme)] = schema["components"]["securitySchemes"].items()
    assert scheme["scheme"] == "bearer"
    for path in ("/revise", "/models/{name}/revise", "/models"):  # inline check or dependency
        method = "get" if path == "/models" else "post"
        assert schema["paths"][path][method]["security"] == [{name: []}], path
    assert "security" not in schema["paths"]["/healthz"]["get"]  # health needs none


def test_the_default_model_takes_its_configuration_from_a_file(tmp_path: Any) -> None:
    path = tmp_path / "shield.json"
    path.write_text(json.dumps({"clustering": {"epsilon": 0.1}, "reviser": {"seed": 9}}))
    with TestClient(create_app(Settings(config=path))) as c:
        config = c.get("/model", params={"tpm": "none", "exact": False}).json()["config"]
    assert config["clustering"]["epsilon"] == 0.1 and config["reviser"]["seed"] == 9


def test_a_state_reports_its_flag_failures_and_next_states(client: TestClient) -> None:
    episode(client)
    crashed = exact(client)["flags"]
    index = int(np.flatnonzero(codec.from_json(crashed)["failures"][:, 0])[0])
    r = client.get(f"/models/default/states/{index}", params={"top": 2})
    assert r.status_code == 200
    state = r.json()
    assert state["failures"] == {"collision": 1, "large_distance": 0}
    assert state["flag"] == "collision"  # 1 failure in a handful of recognitions
    assert state["visits"] >= 1 and len(state["next"]) == 20
    assert all(len(a["states"]) <= 2 for a in state["next"])
    missing = client.get("/models/default/states/999")
    assert missing.status_code == 404 and missing.json()["error"]["field"] == "index"


def test_the_history_holds_the_totals_at_each_episode_end(client: TestClient) -> None:
    for k in range(3):
        episode(client, crash=k != 1)
    r = client.get("/models/default/history")
    assert r.status_code == 200
    history = r.json()
    assert (history["name"], history["stride"]) == ("default", 1)
    assert history["episodes"] == [1, 2, 3] and history["steps"] == [7, 14, 21]
    assert history["failures"] == {"collision": [1, 1, 2], "large_distance": [0, 0, 0]}
    assert history["interventions"].keys() == {"collision", "large_distance"}
    assert history["n_states"][-1] == history["totals"]["n_states"] >= 1
    assert history["totals"] == {
        "episodes": 3,
        "steps": 21,
        "n_states": history["n_states"][-1],
        "model_version": 21,
        "interventions": {c: v[-1] for c, v in history["interventions"].items()},
        "failures": {"collision": 2, "large_distance": 0},
    }
    # the history is part of the model: a restored copy has it and goes on from it
    assert client.put("/models/copy", json=client.get("/model").json()).status_code == 200
    assert client.get("/models/copy/history").json() == {**history, "name": "copy"}
    episode(client, "/models/copy/revise")
    assert client.get("/models/copy/history").json()["episodes"] == [1, 2, 3, 4]
    for path, status, code in (
        ("/models/ghost/history", 404, "unknown_model"),
        ("/models/BAD!/history", 422, "invalid_name"),
    ):
        r = client.get(path)
        assert r.status_code == status and r.json()["error"]["code"] == code, path
        assert r.json()["error"]["field"] == "name"
