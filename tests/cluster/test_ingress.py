"""What a sharded service adds to the contract, in process: each model on its home shard,
batches within a shard, moves that lose no step and that every ingress follows, merged
metrics, a shard that does not answer."""

from __future__ import annotations

import asyncio
import json
import shutil
from pathlib import Path
from typing import Any

from fastapi.testclient import TestClient

from app.cluster import asgi
from app.cluster.ingress import ingress_app, merge_metrics
from app.cluster.placement import hashed_owner
from app.cluster.shard import Gates, Moved, ShardServer
from app.main import create_app
from app.settings import Settings
from tests.cluster.sharded import sharded_client, sharded_clients

NAMES = [f"car-{i}" for i in range(8)]


def step(t: int, done: bool = False) -> dict[str, Any]:
    return {
        "observation": [10.0 + t % 7, 12.0 - t % 5, 9.0],
        "action": 0.5 - 0.1 * (t % 4),
        "done": done,
        "event": "collision" if done else None,
    }


def test_each_model_lives_on_its_home_shard_and_is_listed_once() -> None:
    with sharded_clients(Settings(), n_shards=3) as ([c], servers):
        for name in NAMES:
            assert c.post("/models", json={"name": name}).status_code == 201
        for index, server in enumerate(servers):
            expected = {n for n in [*NAMES, "default"] if hashed_owner(n, 3) == index}
            assert set(server.registry.names()) == expected
        assert [m["name"] for m in c.get("/models").json()["models"]] == sorted([*NAMES, "default"])
        assert c.post("/models", json={"name": NAMES[0]}).json()["error"]["code"] == "model_exists"


def test_a_batch_across_models_of_several_shards_is_refused_and_changes_nothing() -> None:
    with sharded_client(Settings(), n_shards=2) as c:
        a, b = (next(n for n in NAMES if hashed_owner(n, 2) == i) for i in (0, 1))
        together = next(n for n in NAMES if n != a and hashed_owner(n, 2) == 0)
        for name in (a, b, together):
            c.post("/models", json={"name": name})
        r = c.post(
            "/revise/batch", json={"steps": [{**step(0), "model": a}, {**step(1), "model": b}]}
        )
        assert r.status_code == 422
        assert r.json()["error"] == {
            "code": "models_on_several_shards",
            "field": "steps",
            "message": r.json()["error"]["message"],
        }
        assert all(m["model_version"] == 0 for m in c.get("/models").json()["models"])
        r = c.post(
            "/revise/batch",
            json={"steps": [{**step(0), "model": a}, {**step(1), "model": together}]},
        )
        assert r.status_code == 200 and len(r.json()["decisions"]) == 2
        c.post("/shards/move", json={"model": b, "to": 0})  # together now
        r = c.post(
            "/revise/batch", json={"steps": [{**step(2), "model": a}, {**step(3), "model": b}]}
        )
        assert r.status_code == 200 and len(r.json()["decisions"]) == 2


def test_a_moved_model_goes_on_deciding_as_if_it_had_never_moved(tmp_path: Path) -> None:
    plain = TestClient(create_app(Settings()))
    name = NAMES[0]
    home = hashed_owner(name, 2)
    with plain, sharded_clients(Settings(data_dir=tmp_path), n_shards=2) as ([c], servers):
        plain.post("/models", json={"name": name})
        c.post("/models", json={"name": name})
        decisions, expected = [], []
        for t in range(60):
            if t in (20, 40):  # there and back again
                to = 1 - home if t == 20 else home
                r = c.post("/shards/move", json={"model": name, "to": to})
                assert r.status_code == 200 and r.json() == {
                    "model": name,
                    "from": 1 - to,
                    "to": to,
                }
                assert name in servers[to].registry.names()
                assert name not in servers[1 - to].registry.names()
            body = step(t, done=t % 15 == 14)
            decisions.append(c.post(f"/models/{name}/revise", json=body).json())
            expected.append(plain.post(f"/models/{name}/revise", json=body).json())
        assert decisions == expected
        moved_away = [s["moved_away"] for s in c.get("/shards").json()["shards"]]
        assert moved_away[home] == {} and moved_away[1 - home] == {name: home}  # for ingresses
        c.post("/shards/move", json={"model": name, "to": 1 - home})  # that saw it there
        assert c.get("/shards").json()["shards"][home]["moved_away"] == {name: 1 - home}
    with sharded_client(Settings(data_dir=tmp_path), n_shards=2) as c:  # the cluster restarts
        r = c.post(f"/models/{name}/revise", json=step(60))  # a new ingress: sent home first
        assert r.json() == plain.post(f"/models/{name}/revise", json=step(60)).json()
        assert c.delete(f"/models/{name}").status_code == 204
        assert c.post("/models", json={"name": name}).status_code == 201  # where it went


def test_every_ingress_follows_a_move_made_through_another() -> None:
    with sharded_clients(Settings(), n_shards=3, n_ingresses=2) as ([first, second], _):
        name = NAMES[1]
        home = hashed_owner(name, 3)
        first.post("/models", json={"name": name})
        versions = []
        for t, to in enumerate([(home + 1) % 3, (home + 2) % 3, home, (home + 1) % 3]):
            r = first.post("/shards/move", json={"model": name, "to": to})
            assert r.status_code == 200, r.text
            versions.append(
                second.post(f"/models/{name}/revise", json=step(t)).json()["model_version"]
            )
            with second.websocket_connect(f"/models/{name}/ws") as ws:
                ws.send_text(json.dumps(step(t)))
                versions.append(json.loads(ws.receive_text())["model_version"])
        assert versions == list(range(1, 9))


def test_a_move_cut_short_before_its_last_step_leaves_no_second_copy(tmp_path: Path) -> None:
    name = NAMES[2]
    home = hashed_owner(name, 2)
    with sharded_client(Settings(data_dir=tmp_path), n_shards=2) as c:
        c.post("/models", json={"name": name})
        for t in range(10):
            c.post(f"/models/{name}/revise", json=step(t))
        copy = tmp_path / "left-behind"
        shutil.copytree(tmp_path / "shards" / str(home) / "models" / name, copy)
        c.post("/shards/move", json={"model": name, "to": 1 - home})
        c.post(f"/models/{name}/revise", json=step(10))
    shutil.copytree(copy, tmp_path / "shards" / str(home) / "models" / name)  # not deleted
    with sharded_clients(Settings(data_dir=tmp_path), n_shards=2) as ([c], servers):
        assert name not in servers[home].registry.names()
        assert [m["name"] for m in c.get("/models").json()["models"]] == [name, "default"]
        assert c.post(f"/models/{name}/revise", json=step(11)).json()["model_version"] == 12


def test_bad_moves_are_refused_and_change_nothing() -> None:
    with sharded_client(Settings(token="s3cret"), n_shards=2) as c:
        auth = {"Authorization": "Bearer s3cret"}
        assert c.post("/shards/move", json={"model": "default", "to": 0}).status_code == 401
        r = c.post("/shards/move", json={"model": "default", "to": 2}, headers=auth)
        assert (r.status_code, r.json()["error"]["field"]) == (422, "to")
        r = c.post("/shards/move", json={"model": "Bad", "to": 0}, headers=auth)
        assert (r.status_code, r.json()["error"]["code"]) == (422, "invalid_name")
        r = c.post("/shards/move", json={"model": "ghost", "to": 0}, headers=auth)
        assert (r.status_code, r.json()["error"]["code"]) == (404, "unknown_model")
        shards = c.get("/shards", headers=auth).json()["shards"]
        assert [s["moved_away"] for s in shards] == [{}, {}]


def test_a_move_waits_for_the_steps_in_flight_and_holds_the_next() -> None:
    async def scenario() -> list[str]:
        gates, order = Gates(), []

        async def request(name: str, label: str, delay: float) -> None:
            async with gates.use([name]):
                await asyncio.sleep(delay)
                order.append(label)

        async def move() -> None:
            async with gates.exclusive("m"):
                order.append("moved")

        first = asyncio.create_task(request("m", "in flight", 0.05))
        await asyncio.sleep(0.01)
        moving = asyncio.create_task(move())
        await asyncio.sleep(0.01)
        after = asyncio.create_task(request("m", "after", 0.0))
        other = asyncio.create_task(request("n", "other model", 0.0))
        await asyncio.gather(first, moving, after, other)
        return order

    assert asyncio.run(scenario()) == ["other model", "in flight", "moved", "after"]


def test_metrics_are_merged_with_a_shard_label() -> None:
    with sharded_client(Settings(), n_shards=2) as c:
        c.post("/revise", json=step(0))
        text = c.get("/metrics").text
        owner = hashed_owner("default", 2)
        assert (
            f'efsm_http_requests_total{{shard="{owner}",method="POST",route="/revise",'
            'status="200"} 1.0'
        ) in text
        assert text.count("# TYPE efsm_http_requests_total counter") == 1
    merged = merge_metrics(["# TYPE up gauge\nup 1.0\n", '# TYPE up gauge\nup{job="x"} 0.0\n'])
    assert merged == '# TYPE up gauge\nup{shard="0"} 1.0\nup{shard="1",job="x"} 0.0\n'


def test_a_shard_that_does_not_answer_is_a_clear_503_and_others_serve() -> None:
    settings = Settings()
    down = 1 - hashed_owner("default", 2)

    async def call(shard: int, method: str, *args: Any) -> Any:
        if shard == down:
            raise ConnectionError("the replica died")
        return await getattr(live[shard], method)(*args)

    live = [ShardServer(settings, i, call) for i in range(2)]
    with TestClient(ingress_app(settings, 2, call, None)) as c:  # type: ignore[arg-type]
        name = next(n for n in NAMES if hashed_owner(n, 2) == down)
        r = c.post(f"/models/{name}/revise", json=step(0))
        assert r.status_code == 503 and r.json()["error"]["code"] == "shard_unavailable"
        assert c.get("/readyz").status_code == 503
        assert c.post("/revise", json=step(0)).status_code == 200
        with c.websocket_connect(f"/models/{name}/ws") as ws:
            assert json.loads(ws.receive_text())["error"]["code"] == "shard_unavailable"


def test_a_streamed_answer_passes_on_as_it_comes_and_stops_when_the_reader_leaves() -> None:
    finished = []

    async def app(scope: Any, receive: Any, send: Any) -> None:
        await send({"type": "http.response.start", "status": 200, "headers": []})
        try:
            for piece in range(1000):
                await send(
                    {"type": "http.response.body", "body": b"%d;" % piece, "more_body": True}
                )
                await asyncio.sleep(0)
        finally:
            finished.append(True)

    async def read() -> list[Any]:
        parts: list[Any] = []
        async for part in asgi.stream(app, asgi.Request("GET", "/")):
            parts.append(part)
            if len(parts) == 4:
                break
        await asyncio.sleep(0.01)
        return parts

    parts = asyncio.run(read())
    assert parts[0] == asgi.Reply(200, (), b"") and parts[1:] == [b"0;", b"1;", b"2;"]
    assert finished == [True]  # the app was stopped, not left running


def test_a_shard_streams_the_live_feed_and_ends_it_once_the_model_moved() -> None:
    with sharded_clients(Settings(), n_shards=2) as ([c], servers):
        home = hashed_owner("default", 2)

        async def watch() -> list[Any]:
            parts, seen = [], servers[home].stream(asgi.Request("GET", "/models/default/events"))
            async for part in seen:
                parts.append(part)
                if len(parts) == 2:  # the head and the hello: step, then move
                    await servers[home].request(
                        asgi.Request(
                            "POST",
                            "/revise",
                            b"",
                            ((b"content-type", b"application/json"),),
                            json.dumps(step(0)).encode(),
                        )
                    )
                if len(parts) == 3:
                    moved = await servers[home].move("default", 1 - home)
                    assert isinstance(moved, asgi.Reply) and moved.status == 200
            return parts

        parts = asyncio.run(asyncio.wait_for(watch(), 30))
        assert parts[0].status == 200
        assert json.loads(parts[1].decode().split("data: ")[1])["type"] == "hello"
        assert json.loads(parts[2].decode().split("data: ")[1])["type"] == "step"
        assert len(parts) == 3  # ended after the move

        async def reconnect() -> Any:
            return await anext(servers[home].stream(asgi.Request("GET", "/models/default/events")))

        assert asyncio.run(reconnect()) == Moved("default", 1 - home)


def test_a_moved_model_answers_a_step_sent_again_with_its_first_decision() -> None:
    with sharded_client(Settings(), n_shards=2) as c:
        name = NAMES[2]
        c.post("/models", json={"name": name})
        body = {**step(0), "idempotency_key": "before-the-move"}
        first = c.post(f"/models/{name}/revise", json=body).json()
        to = 1 - hashed_owner(name, 2)
        assert c.post("/shards/move", json={"model": name, "to": to}).status_code == 200
        assert c.post(f"/models/{name}/revise", json=body).json() == first
        assert c.get(f"/models/{name}", params={"tpm": "none"}).json()["model_version"] == 1
