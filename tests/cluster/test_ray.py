"""The sharded service on Ray Serve, as a user starts it (``python -m app serve-ray``, a local
Ray instance, served on 127.0.0.1, two shards and two ingresses, ``fsync always``): the
contract through it, a shard killed mid-stream, a model moved between shards while it is
written."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
from fastapi.testclient import TestClient
from websocket import create_connection

from app.cluster.placement import hashed_owner
from app.main import create_app
from app.settings import Settings
from tests.conftest import free_port

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
# one worker runs this group, one test after another: one Ray instance at a time, and never
# beside a test that times the service (a Ray instance keeps a small machine's cores busy)
pytestmark = pytest.mark.xdist_group("ray")


def step(t: int) -> dict[str, Any]:
    done = t % 25 == 24
    return {
        "observation": [10.0 + t % 9, 12.0 - t % 6, 9.0 + t % 4],
        "action": 0.6 - 0.15 * (t % 5),
        "done": done,
        "event": "collision" if done else None,
    }


class Cluster:
    """``python -m app serve-ray`` in its own process."""

    def __init__(self, data_dir: Path) -> None:
        self.log = data_dir.parent / "serve-ray.log"
        # The port is free when chosen, but Ray's own processes take ports while it starts:
        # when one of them took it first, the proxy cannot bind, and the cluster starts again
        # on another.
        for _ in range(3):
            if self._start(data_dir):
                return
            if "Failed to bind to address" not in self.log.read_text():
                break
        raise RuntimeError(f"serve-ray exited: {self.log.read_text()[-3000:]}")

    def _start(self, data_dir: Path) -> bool:
        """Start it on a free port; whether it came up (False: it exited)."""
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.process = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "app",
                "serve-ray",
                "--host",
                "127.0.0.1",
                "--port",
                str(self.port),
                "--data-dir",
                str(data_dir),
                "--shards",
                "2",
                "--ingresses",
                "2",
                "--fsync",
                "always",
                "--ray-cpus",
                "2",
            ],
            stdout=open(self.log, "wb"),
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )
        deadline = time.monotonic() + 180
        while time.monotonic() < deadline:
            if self.process.poll() is not None:
                try:  # whatever it left running in its session
                    os.killpg(self.process.pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
                return False
            try:
                if httpx.get(self.url + "/readyz", timeout=2).status_code == 200:
                    return True
            except httpx.TransportError:
                pass
            time.sleep(0.5)
        self.stop()
        raise RuntimeError(f"serve-ray did not start: {self.log.read_text()[-3000:]}")

    def owner_pid(self, name: str) -> int:
        shards = httpx.get(self.url + "/shards", timeout=30).json()["shards"]
        pid: int = next(s["pid"] for s in shards if name in s["models"])
        return pid

    def stop(self) -> None:
        self.process.send_signal(signal.SIGTERM)
        try:
            self.process.wait(60)
        except subprocess.TimeoutExpired:
            os.killpg(self.process.pid, signal.SIGKILL)
            self.process.wait(10)


@pytest.fixture(scope="module")
def cluster(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Cluster]:
    running = Cluster(tmp_path_factory.mktemp("ray") / "data")
    yield running
    running.stop()
    assert running.process.returncode == 0, running.log.read_text()[-3000:]


@pytest.fixture
def plain() -> Iterator[TestClient]:
    """The plain service in process: what every decision must equal."""
    with TestClient(create_app(Settings())) as client:
        yield client


def post(url: str, body: dict[str, Any]) -> httpx.Response:
    """POST, sent again while the model's shard restarts (503, or no answer at all)."""
    deadline = time.monotonic() + 90
    while True:
        try:
            response = httpx.post(url, json=body, timeout=60)
            if response.status_code != 503 or time.monotonic() > deadline:
                return response
        except httpx.TransportError:
            if time.monotonic() > deadline:
                raise
        time.sleep(0.2)


def test_the_contract_through_ray(cluster: Cluster, plain: TestClient) -> None:
    u = cluster.url
    r = httpx.post(u + "/revise", json=step(0))
    assert r.status_code == 200 and r.json() == plain.post("/revise", json=step(0)).json()
    for name in ("car-1", "car-2", "car-3"):
        assert httpx.post(u + "/models", json={"name": name}).status_code == 201
        plain.post("/models", json={"name": name})
    assert httpx.post(u + "/models", json={"name": "car-1"}).status_code == 409
    bad = httpx.post(u + "/models/car-1/revise", json={"observation": [1, 2], "action": 0})
    assert (bad.status_code, bad.json()["error"]["code"]) == (422, "invalid_observation")
    assert httpx.post(u + "/models/ghost/revise", json=step(0)).status_code == 404
    batch = {"steps": [step(t) for t in range(30)]}
    r = httpx.post(u + "/models/car-1/revise/batch", json=batch)
    assert r.json() == plain.post("/models/car-1/revise/batch", json=batch).json()
    ws = create_connection(u.replace("http", "ws") + "/models/car-2/ws")
    for t in range(20):
        ws.send(json.dumps(step(t)))
        assert json.loads(ws.recv()) == plain.post("/models/car-2/revise", json=step(t)).json()
    ws.send("{not json")
    assert "invalid_json" in ws.recv()
    ws.close()
    snapshot = httpx.get(u + "/models/car-1", params={"format": "npz"}).content
    put = httpx.put(
        u + "/models/car-3", content=snapshot, headers={"content-type": "application/x-npz"}
    )
    assert put.status_code == 200 and put.json()["model_version"] == 30
    names = [m["name"] for m in httpx.get(u + "/models").json()["models"]]
    assert names == ["car-1", "car-2", "car-3", "default"]
    assert 'shard="' in httpx.get(u + "/metrics").text


def test_a_killed_shard_comes_back_with_every_acknowledged_step(
    cluster: Cluster, plain: TestClient
) -> None:
    u, name = cluster.url, "killed"
    assert httpx.post(u + "/models", json={"name": name}).status_code == 201
    plain.post("/models", json={"name": name})
    for t in range(120):
        if t == 60:  # mid-stream, after 60 acknowledged steps: the process dies, no goodbye
            pid = cluster.owner_pid(name)
            os.kill(pid, signal.SIGKILL)
        r = post(f"{u}/models/{name}/revise", step(t))
        assert r.status_code == 200, r.text
        assert r.json() == plain.post(f"/models/{name}/revise", json=step(t)).json()
    assert cluster.owner_pid(name) != pid  # Serve started a new replica, which loaded the files
    assert r.json()["model_version"] == 120


def test_a_model_moves_between_shards_under_load_without_losing_a_step(
    cluster: Cluster, plain: TestClient
) -> None:
    u = cluster.url
    moved, other = "moved", "beside"
    for name in (moved, other):
        assert httpx.post(u + "/models", json={"name": name}).status_code == 201
        plain.post("/models", json={"name": name})
    answers: dict[str, list[dict[str, Any]]] = {moved: [], other: []}
    stop = threading.Event()

    def write(name: str) -> None:
        with httpx.Client(timeout=60) as client:
            t = 0
            while not stop.is_set() or t < 40:
                r = client.post(f"{u}/models/{name}/revise", json=step(t))
                assert r.status_code == 200, r.text
                answers[name].append(r.json())
                t += 1

    writers = [threading.Thread(target=write, args=(n,)) for n in (moved, other)]
    for writer in writers:
        writer.start()
    home = hashed_owner(moved, 2)
    for to in (1 - home, home, 1 - home):
        time.sleep(0.3)
        r = httpx.post(u + "/shards/move", json={"model": moved, "to": to}, timeout=60)
        assert r.status_code == 200 and r.json()["to"] == to, r.text
    stop.set()
    for writer in writers:
        writer.join(120)
    for name in (moved, other):
        expected = [
            plain.post(f"/models/{name}/revise", json=step(t)).json()
            for t in range(len(answers[name]))
        ]
        assert answers[name] == expected
    shards = httpx.get(u + "/shards").json()
    assert moved in shards["shards"][1 - home]["models"]
    assert moved not in shards["shards"][home]["models"]


def test_the_live_feed_through_ray_ends_at_a_move_and_resumes_where_the_model_went(
    cluster: Cluster,
) -> None:
    u, name = cluster.url, "watched"
    assert httpx.post(u + "/models", json={"name": name}).status_code == 201

    def events(lines: Iterator[str]) -> Iterator[dict[str, Any]]:
        for line in lines:
            if line.startswith("data: "):
                yield json.loads(line[6:])

    with httpx.stream("GET", f"{u}/models/{name}/events", timeout=60) as response:
        feed = events(response.iter_lines())
        assert next(feed)["type"] == "hello"
        httpx.post(f"{u}/models/{name}/revise", json=step(0))
        assert next(feed)["decision"]["model_version"] == 1
        home = hashed_owner(name, 2)
        assert (
            httpx.post(u + "/shards/move", json={"model": name, "to": 1 - home}).status_code == 200
        )
        began = time.monotonic()
        after = {e["type"] for e in feed}  # until the stream ends, at the feed's next ping
        assert after == {"ping"} and time.monotonic() - began < 30
    with httpx.stream("GET", f"{u}/models/{name}/events", timeout=60) as response:
        hello = next(events(response.iter_lines()))
        assert hello["type"] == "hello" and hello["model_version"] == 1


@pytest.mark.skipif(CHROMIUM is None, reason="needs Debian's chromium (.ci/run installs it)")
def test_the_dashboard_follows_a_model_through_ray(cluster: Cluster) -> None:
    playwright = pytest.importorskip("playwright.sync_api")
    u, name = cluster.url, "dashboard"
    assert httpx.post(u + "/models", json={"name": name}).status_code == 201
    for t in range(80):
        httpx.post(f"{u}/models/{name}/revise", json=step(t))
    with playwright.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=["--no-sandbox"])
        page = browser.new_page()
        errors: list[str] = []
        page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
        page.on("pageerror", lambda e: errors.append(str(e)))
        page.goto(f"{u}/dashboard")
        page.select_option("#model", name)
        page.wait_for_function(
            f"document.getElementById('status').textContent == 'live: {name}'", timeout=20000
        )
        probe = httpx.post(
            f"{u}/models/{name}/revise", json={**step(80), "observation": [31.0, 400.0, 1.0]}
        ).json()
        assert probe["new_state"]  # far beyond the stream: a new state, which the page shows
        page.wait_for_function(
            f"document.getElementById('state-count').textContent == '{probe['n_states']}'",
            timeout=10000,
        )
        browser.close()
    assert errors == []


def test_a_data_directory_of_another_cluster_size_is_refused_in_one_line(tmp_path: Path) -> None:
    (tmp_path / "cluster.json").write_text('{"shards": 2}')
    done = subprocess.run(
        [sys.executable, "-m", "app", "serve-ray", "--shards", "3", "--data-dir", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 1
    assert done.stderr.strip().splitlines()[-1] == (
        f"{tmp_path} holds a cluster of 2 shards, not 3: its models stay on the shards that "
        "hold their files; start it with the same number"
    )
