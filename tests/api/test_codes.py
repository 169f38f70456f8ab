"""Inputs that used to get answers outside the documented table (issue #45, finding 8)."""

from __future__ import annotations

from collections.abc import Iterator

from fastapi.testclient import TestClient

from app.main import create_app
from app.settings import Settings

JSON = {"content-type": "application/json"}


def test_a_body_that_is_not_json_is_invalid_json(client: TestClient) -> None:
    for body in (b'\xff\xfe{"observation": [1, 2, 3]}', b"[" * 1000 + b"]" * 1000):
        r = client.post("/revise", content=body, headers=JSON)
        assert r.status_code == 422
        assert r.json()["error"] | {"message": ""} == {
            "code": "invalid_json",
            "message": "",
            "field": None,
        }


def test_a_streamed_body_over_the_limit_is_too_large(client: TestClient) -> None:
    def chunks() -> Iterator[bytes]:
        for _ in range(12):  # 12 MiB against the default limit of 8 MiB, no content-length
            yield bytes(2**20)

    r = client.post("/revise", content=chunks(), headers=JSON)
    assert r.status_code == 413 and r.json()["error"]["code"] == "too_large"
    assert client.get("/model", params={"tpm": "none"}).json()["steps"] == 0


def test_an_action_bin_or_state_the_model_lacks_is_named(client: TestClient) -> None:
    client.post("/revise", json={"observation": [10.0, 20.0, 10.0], "action": 0.1})
    r = client.get("/models/default", params={"action": 20})
    assert (r.status_code, r.json()["error"]["code"], r.json()["error"]["field"]) == (
        422,
        "invalid_query",
        "action",
    )
    r = client.get("/models/default/states/5")
    assert (r.status_code, r.json()["error"]["code"], r.json()["error"]["field"]) == (
        404,
        "not_found",
        "index",
    )


def test_the_openapi_schema_names_the_codes_a_client_can_meet(client: TestClient) -> None:
    schema = client.get("/openapi.json").json()
    paths = schema["paths"]
    assert "409" in paths["/models"]["post"]["responses"]
    assert "503" in paths["/models/{name}/revise"]["post"]["responses"]
    assert "text/plain" in paths["/metrics"]["get"]["responses"]["200"]["content"]
    index = next(
        p
        for p in paths["/models/{name}/states/{index}"]["get"]["parameters"]
        if p["name"] == "index"
    )
    assert index["schema"]["minimum"] == 0
    assert client.get("/models/default/states/-1").json()["error"]["code"] == "invalid_path"


def test_an_unknown_query_parameter_is_refused_as_an_unknown_body_field_is(
    client: TestClient,
) -> None:
    step = {"observation": [10.0, 20.0, 10.0], "action": 0.1}
    r = client.post("/revise", params={"learn": "false"}, json=step)  # a body field, misplaced
    assert (r.status_code, r.json()["error"]["code"], r.json()["error"]["field"]) == (
        422,
        "invalid_query",
        "learn",
    )
    r = client.get("/models/default", params={"tmp": "none"})  # tpm, misspelt
    assert (r.status_code, r.json()["error"]["code"], r.json()["error"]["field"]) == (
        422,
        "invalid_query",
        "tmp",
    )
    assert "tpm" in r.json()["error"]["message"]  # what the route does take
    assert client.get("/model", params={"tpm": "none"}).json()["steps"] == 0  # nothing applied
    with client.websocket_connect("/ws?colour=red") as ws:
        assert ws.receive_json()["error"] | {"message": ""} == {
            "code": "invalid_query",
            "message": "",
            "field": "colour",
        }
    with client.websocket_connect("/ws?token=") as ws:  # a stream may carry its token there
        ws.send_json(step)
        assert ws.receive_json()["model_version"] == 1


def test_an_unknown_query_parameter_without_the_token_is_unauthorized() -> None:
    with TestClient(create_app(Settings(token="secret"))) as client:
        r = client.get("/models/default", params={"tmp": "none"})
        assert (r.status_code, r.json()["error"]["code"]) == (401, "unauthorized")


def test_a_method_a_route_does_not_take_is_405_with_the_error_body(client: TestClient) -> None:
    r = client.delete("/healthz")
    assert r.status_code == 405
    assert r.json()["error"] | {"message": ""} == {
        "code": "method_not_allowed",
        "message": "",
        "field": None,
    }


def test_a_configuration_without_criteria_is_refused(client: TestClient) -> None:
    # it could learn no failure and would pass every proposal: a shield in name only
    r = client.post("/models", json={"name": "blind", "config": {"criteria": []}})
    assert (r.status_code, r.json()["error"]["code"], r.json()["error"]["field"]) == (
        422,
        "invalid_config",
        "config.criteria",
    )
    assert client.get("/models/blind").status_code == 404
