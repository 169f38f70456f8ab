"""What one connection may take of a real server (issue #69, items 6 and 9): half-sent
requests time out, connections are bounded, and refusals at the protocol level carry the
service's error body (app/api/connections.py)."""

from __future__ import annotations

import json
import selectors
import socket
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
import websocket

from app.settings import Settings
from tests.conftest import Server, start_server

pytestmark = pytest.mark.slow  # each test starts a real server

TIMEOUT = 1.0  # [s] the header and body time-outs of the server under test
LIMIT = 150  # its most connections


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Server]:
    data = tmp_path_factory.mktemp("connections") / "data"
    running = start_server(
        data,
        "--header-timeout",
        str(TIMEOUT),
        "--body-timeout",
        str(TIMEOUT),
        "--max-connections",
        str(LIMIT),
        "--max-body-bytes",
        "2048",
    )
    yield running
    running.stop()


def address(server: Server) -> tuple[str, int]:
    host, port = server.url.removeprefix("http://").split(":")
    return host, int(port)


def until_closed(sockets: list[socket.socket], seconds: float) -> dict[socket.socket, bytes]:
    """Everything each socket receives until the server closes it (or ``seconds`` pass)."""
    received = {s: b"" for s in sockets}
    with selectors.DefaultSelector() as selector:
        for s in sockets:
            selector.register(s, selectors.EVENT_READ)
        deadline = time.monotonic() + seconds
        while selector.get_map() and time.monotonic() < deadline:
            for key, _ in selector.select(timeout=0.1):
                ready = key.fileobj
                assert isinstance(ready, socket.socket)
                chunk = ready.recv(65536)
                received[ready] += chunk
                if not chunk:
                    selector.unregister(ready)
        assert not selector.get_map(), f"{len(selector.get_map())} sockets still open"
    return received


def error_of(response: bytes) -> tuple[int, dict[str, Any]]:
    """The status and the error of a raw HTTP response."""
    head, _, body = response.partition(b"\r\n\r\n")
    return int(head.split()[1]), json.loads(body)["error"]


def test_half_sent_requests_are_answered_408_and_closed_while_others_are_served(
    server: Server,
) -> None:
    opened = time.monotonic()
    line_only = [socket.create_connection(address(server)) for _ in range(80)]
    for s in line_only:  # the request line and one header, never the end of the headers
        s.sendall(b"POST /revise HTTP/1.1\r\nHost: shield\r\n")
    body_stalled = [socket.create_connection(address(server)) for _ in range(20)]
    for s in body_stalled:
        s.sendall(
            b"POST /revise HTTP/1.1\r\nHost: shield\r\ncontent-type: application/json"
            b'\r\nContent-Length: 100\r\n\r\n{"observation": ['
        )
    kept_alive = socket.create_connection(address(server))  # the second request half-sent
    kept_alive.sendall(b"GET /healthz HTTP/1.1\r\nHost: shield\r\n\r\n")
    assert kept_alive.recv(65536).startswith(b"HTTP/1.1 200")
    kept_alive.sendall(b"GET /healthz HTTP/1.1\r\n")
    step = {"observation": [10.0, 50.0, 12.0], "action": 0.5}
    assert httpx.post(server.url + "/revise", json=step).status_code == 200  # served meanwhile

    received = until_closed([*line_only, *body_stalled, kept_alive], seconds=10 * TIMEOUT)
    assert time.monotonic() - opened >= 0.9 * TIMEOUT  # not before the time-out
    for s, response in received.items():
        status, error = error_of(response)
        assert (status, error["code"]) == (408, "request_timeout"), response
        s.close()
    assert "body" in error_of(received[body_stalled[0]])[1]["message"]
    # the stalled bodies changed nothing: only the one whole step counted
    model = httpx.get(server.url + "/models/default", params={"tpm": "none"}).json()
    assert model["model_version"] == 1


def test_a_connection_beyond_the_limit_is_answered_503_then_served_once_others_close(
    server: Server,
) -> None:
    idle = [socket.create_connection(address(server)) for _ in range(LIMIT)]
    try:
        time.sleep(0.2)  # the server has accepted them all
        refused = httpx.get(server.url + "/healthz")
        assert refused.status_code == 503
        assert refused.json()["error"]["code"] == "overloaded"
    finally:
        for s in idle:
            s.close()
    time.sleep(0.2)
    assert httpx.get(server.url + "/healthz").status_code == 200


def test_a_request_the_parser_cannot_read_gets_the_error_body(server: Server) -> None:
    with socket.create_connection(address(server)) as s:
        s.sendall(b"GET / HTTP/1.1\r\nHost\x00: shield\r\n\r\n")
        status, error = error_of(until_closed([s], seconds=5)[s])
    assert (status, error["code"]) == (400, "bad_request") and error["message"]


def test_headers_over_their_limit_get_431_and_a_large_body_does_not(server: Server) -> None:
    with socket.create_connection(address(server)) as s:
        s.sendall(b"GET /healthz HTTP/1.1\r\nHost: shield\r\nX-Big: " + b"a" * 2**20)
        status, error = error_of(until_closed([s], seconds=5)[s])
    assert (status, error["code"]) == (431, "headers_too_large")
    body = b"x" * 200_000  # headers and body in one write: only the headers count
    with socket.create_connection(address(server)) as s:
        s.sendall(
            b"PUT /models/big HTTP/1.1\r\nHost: shield\r\nConnection: close\r\n"
            b"Content-Type: application/json\r\nContent-Length: %d\r\n\r\n" % len(body) + body
        )
        status, error = error_of(until_closed([s], seconds=10)[s])
    assert (status, error["code"]) == (422, "invalid_snapshot")


@pytest.mark.parametrize("size", [5_000, 2_000_000])
def test_a_websocket_frame_over_twice_the_limit_is_closed_with_1009(
    server: Server, size: int
) -> None:
    ws = websocket.create_connection(server.url.replace("http", "ws") + "/ws", timeout=10)
    try:
        ws.send(
            json.dumps({"observation": [10.0, 50.0, 12.0], "action": 0.5, "stream": "s" * size})
        )
        opcode, data = ws.recv_data(control_frame=True)
    finally:
        ws.close()
    assert opcode == websocket.ABNF.OPCODE_CLOSE
    assert int.from_bytes(data[:2], "big") == 1009  # message too big, as RFC 6455 names it


def test_the_limits_are_settings_with_documented_defaults() -> None:
    defaults = Settings()
    assert (
        defaults.header_timeout,
        defaults.body_timeout,
        defaults.keep_alive_timeout,
        defaults.max_connections,
    ) == (10.0, 20.0, 5, 1000)
    api = (Path(__file__).parents[2] / "docs" / "api.md").read_text()
    for option in ("header_timeout", "body_timeout", "keep_alive_timeout", "max_connections"):
        assert f"`{option}`" in api
