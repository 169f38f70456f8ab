"""A bounded battery of hostile requests against a real server: 5xx answers and changed models.

Starts ``python -m app serve`` on 127.0.0.1 (a temporary data directory, short read time-outs,
a 64 KiB body limit) and sends what a buggy or hostile client might: malformed JSON, wrong
types, huge and non-finite numbers, oversized bodies, batches and frames, unknown fields and
query parameters, hostile model configurations, mutated snapshots and archives, unreadable
HTTP, and sockets that send half a request and stop. Each probe goes over HTTP, a raw socket or
a WebSocket; every refused probe is followed by a look at every model (the exact state of each,
and the list of models), and every accepted configuration or snapshot by a step and a read of
the model it made. Printed: the probes sent, the answers of 5xx (a WebSocket's ``internal``
error frame, or a connection dropped without an answer, counts as one), the probes that changed
a model although refused, and the half-sent sockets still open after the time-out.

Goals: 0 answers of 5xx, 0 changed models, 0 sockets left open. A new refusal is covered by
adding a generator of probes with ``@battery("name")`` (see :func:`configs` for the pattern).

    python bench/hostile.py                 # every battery, about a minute
    python bench/hostile.py --only configs snapshots --json bench/results/hostile.json
"""

from __future__ import annotations

import argparse
import hashlib
import io
import json
import os
import re
import socket
import subprocess
import sys
import tempfile
import time
import zipfile
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import websocket

SEED = 0
BODY_LIMIT = 64 * 1024  # [bytes] the server's --max-body-bytes
MAX_BATCH = 64  # the server's --max-batch
TIMEOUT = 2.0  # [s] its --header-timeout and --body-timeout
STEP = {"observation": [10.0, 50.0, 12.0], "action": 0.5}


@dataclass
class Probe:
    """One hostile input. ``http``: (method, path, body bytes or None, headers); ``raw``: the
    bytes written to a fresh socket; ``ws``: one frame (text or bytes) on ``/ws``. ``then``:
    the model a 2xx answer made, which is then stepped and read."""

    battery: str
    label: str
    http: tuple[str, str, bytes | None, dict[str, str]] | None = None
    raw: bytes | None = None
    ws: str | bytes | None = None
    then: str | None = None


@dataclass
class Outcome:
    probe: Probe
    answer: str  # "422 invalid_body", "ws 1009", "reset", ...
    server_error: bool
    changed: bool = False


@dataclass
class Report:
    outcomes: list[Outcome] = field(default_factory=list)
    half_sent: int = 0
    half_sent_open: int = 0

    def summary(self) -> dict[str, Any]:
        by_battery: dict[str, Counter[str]] = {}
        answers: dict[str, Counter[str]] = {}
        for o in self.outcomes:
            counts = by_battery.setdefault(o.probe.battery, Counter())
            counts["probes"] += 1
            counts["5xx"] += o.server_error
            counts["changed"] += o.changed
            answers.setdefault(o.probe.battery, Counter())[o.answer.split(";")[0]] += 1
        return {
            "probes": len(self.outcomes) + self.half_sent,
            "5xx": sum(o.server_error for o in self.outcomes),
            "changed": sum(o.changed for o in self.outcomes),
            "half_sent": self.half_sent,
            "half_sent_open": self.half_sent_open,
            "batteries": {name: dict(c) for name, c in by_battery.items()},
            "answers": {name: dict(c.most_common()) for name, c in answers.items()},
            "failures": [
                f"{o.probe.battery}/{o.probe.label}: {o.answer}"
                + (" (changed a model)" if o.changed else "")
                for o in self.outcomes
                if o.server_error or o.changed
            ],
        }


BATTERIES: dict[str, Callable[[httpx.Client], Iterator[Probe]]] = {}


def battery(
    name: str,
) -> Callable[
    [Callable[[httpx.Client], Iterator[Probe]]], Callable[[httpx.Client], Iterator[Probe]]
]:
    """Register a generator of probes (it may read the server, e.g. a snapshot to mutate)."""

    def register(
        make: Callable[[httpx.Client], Iterator[Probe]],
    ) -> Callable[[httpx.Client], Iterator[Probe]]:
        BATTERIES[name] = make
        return make

    return register


def post(
    battery_name: str,
    label: str,
    path: str,
    body: bytes | str,
    then: str | None = None,
    method: str = "POST",
    content_type: str = "application/json",
) -> Probe:
    data = body.encode() if isinstance(body, str) else body
    return Probe(
        battery_name, label, http=(method, path, data, {"content-type": content_type}), then=then
    )


HUGE = ["1e308", "-1e308", "1.7976931348623157e308", "5e-324", "1e309", "-1e400", "1" + "0" * 400]
NON_FINITE = ["NaN", "Infinity", "-Infinity", "1e999"]
WRONG = ['"10"', "true", "null", "{}", "[]", "[[1, 2, 3]]", '"NaN"', '{"$gt": 0}']


@battery("json")
def malformed(_: httpx.Client) -> Iterator[Probe]:
    bodies = [
        b"",
        b"{",
        b"[",
        b"}",
        b"{'observation': [1]}",
        b'{"observation": [1, 2, 3],}',
        b'{"observation": [1, 2, 3], "action": 0.5} trailing',
        b"\xff\xfe{}",
        b"[" * 5000 + b"]" * 5000,
        b'{"a":' * 3000 + b"1" + b"}" * 3000,
        b"\x00" * 64,
        b'{"observation": [1, 2, 3], "action": 0.5, "action": "x"}',
        '{"observation": [1, 2, 3], "action": "\ud800"}'.encode("utf-8", "surrogatepass"),
        b'"just a string"',
        b"12345",
        b"null",
    ]
    for i, body in enumerate(bodies):
        for path in ("/revise", "/revise/batch", "/models"):
            yield post("json", f"{path} #{i}", path, body)
        yield Probe("json", f"ws #{i}", ws=body.decode("utf-8", "replace"))
    yield post(
        "json",
        "form content type",
        "/revise",
        json.dumps(STEP),
        content_type="application/x-www-form-urlencoded",
    )


@battery("types")
def wrong_types(_: httpx.Client) -> Iterator[Probe]:
    for name in (
        "observation",
        "action",
        "stream",
        "event",
        "done",
        "applied_action",
        "learn",
        "shadow",
    ):
        for value in WRONG:
            body = json.dumps(STEP)[:-1] + f', "{name}": {value}}}'
            yield post("types", f"{name}={value}", "/revise", body)
            yield Probe("types", f"ws {name}={value}", ws=body)
    for value in WRONG:
        yield post("types", f"steps={value}", "/revise/batch", f'{{"steps": {value}}}')
        yield post(
            "types",
            f"observation item {value}",
            "/revise",
            f'{{"observation": [1, {value}, 3], "action": 0.5}}',
        )


@battery("numbers")
def numbers(_: httpx.Client) -> Iterator[Probe]:
    for value in HUGE + NON_FINITE:
        for body in (
            f'{{"observation": [{value}, 50, 12], "action": 0.5}}',
            f'{{"observation": [10, 50, 12], "action": {value}}}',
            f'{{"observation": [10, 50, 12], "action": 0.5, "applied_action": {value}}}',
            f'{{"steps": [{json.dumps(STEP)}, {{"observation": [{value}, 1, 1], "action": 0}}]}}',
        ):
            path = "/revise/batch" if body.startswith('{"steps"') else "/revise"
            yield post("numbers", f"{path} {body[:60]}", path, body)
        yield Probe(
            "numbers",
            f"ws observation {value}",
            ws=f'{{"observation": [{value}, 50, 12], "action": 0.5}}',
        )
        yield Probe(
            "numbers", f"?action={value}", http=("GET", f"/models/default?action={value}", None, {})
        )
        yield Probe(
            "numbers",
            f"?min_prob={value}",
            http=("GET", f"/models/default?min_prob={value}", None, {}),
        )
    yield Probe(
        "numbers",
        "state index 10**30",
        http=("GET", "/models/default/states/" + "1" + "0" * 30, None, {}),
    )


@battery("oversized")
def oversized(_: httpx.Client) -> Iterator[Probe]:
    big = json.dumps({**STEP, "stream": "s" * BODY_LIMIT})
    yield post("oversized", "body over the limit", "/revise", big)
    yield Probe(
        "oversized",
        "declared length far over",
        raw=(
            b"POST /revise HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n"
            b"Content-Length: 1000000000000\r\n\r\n{}"
        ),
    )
    yield post(
        "oversized",
        "batch over max_batch",
        "/revise/batch",
        json.dumps({"steps": [STEP] * (MAX_BATCH + 1)}),
    )
    yield post(
        "oversized",
        "observation of 5000",
        "/revise",
        json.dumps({"observation": [1.0] * 5000, "action": 0.5}),
    )
    yield post("oversized", "model name of 10,000", "/models", json.dumps({"name": "m" * 10_000}))
    yield Probe("oversized", "frame just over the limit", ws=big)
    yield Probe(
        "oversized",
        "frame over twice the limit",
        ws=json.dumps({**STEP, "stream": "s" * (4 * BODY_LIMIT)}),
    )
    yield Probe("oversized", "binary frame", ws=b"\x00" * 128)
    yield Probe(
        "oversized",
        "headers of 1 MiB",
        raw=b"GET /healthz HTTP/1.1\r\nHost: x\r\n" + b"X-Big: " + b"a" * 2**20 + b"\r\n\r\n",
    )
    yield Probe(
        "oversized",
        "chunked body over the limit",
        raw=(
            b"POST /revise HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n"
            b"Transfer-Encoding: chunked\r\n\r\n"
            + b"".join(b"4000\r\n" + b" " * 0x4000 + b"\r\n" for _ in range(8))
            + b"0\r\n\r\n"
        ),
    )


@battery("unknown")
def unknown(_: httpx.Client) -> Iterator[Probe]:
    yield post("unknown", "body field", "/revise", json.dumps({**STEP, "colour": "red"}))
    yield post(
        "unknown",
        "batch step field",
        "/revise/batch",
        json.dumps({"steps": [{**STEP, "colour": 1}]}),
    )
    yield post("unknown", "query on a step", "/revise?learn=false", json.dumps(STEP))
    yield Probe("unknown", "query on a read", http=("GET", "/models/default?tmp=none", None, {}))
    yield post(
        "unknown",
        "config key",
        "/models",
        json.dumps({"name": "u1", "config": {"colour": 1}}),
        then="u1",
    )
    yield post(
        "unknown",
        "nested config key",
        "/models",
        json.dumps({"name": "u2", "config": {"clustering": {"rho2": 1}}}),
        then="u2",
    )
    yield Probe("unknown", "ws field", ws=json.dumps({**STEP, "colour": "red"}))
    yield Probe("unknown", "no route", http=("GET", "/admin", None, {}))
    yield Probe("unknown", "method", http=("DELETE", "/healthz", None, {}))
    yield Probe(
        "unknown",
        "unknown model step",
        http=(
            "POST",
            "/models/nobody/revise",
            json.dumps(STEP).encode(),
            {"content-type": "application/json"},
        ),
    )


@battery("http")
def unreadable_http(_: httpx.Client) -> Iterator[Probe]:
    for i, data in enumerate(
        [
            b"GARBAGE\r\n\r\n",
            b"GET / HTTP/9.9\r\n\r\n",
            b"GET / HTTP/1.1\r\nHost\x00: x\r\n\r\n",
            b"POST /revise HTTP/1.1\r\nContent-Length: -5\r\n\r\n",
            b"POST /revise HTTP/1.1\r\nContent-Length: 5\r\n"
            b"Transfer-Encoding: chunked\r\n\r\n0\r\n\r\n",
            b"\x16\x03\x01\x00\xa5\x01\x00\x00\xa1\x03\x03",
        ]
    ):  # a TLS hello
        yield Probe("http", f"raw #{i}", raw=data)


@battery("configs")
def configs(_: httpx.Client) -> Iterator[Probe]:
    """Issue #69, items 2 and 3: every number of a configuration finite and in range, every
    size bounded. A 2xx is followed by a step and a read of the model made."""
    hostile: list[tuple[str, str]] = [
        ("min_variance Infinity", '{"clustering": {"min_variance": Infinity}}'),
        ("min_variance NaN", '{"clustering": {"min_variance": NaN}}'),
        ("rho 1e308", '{"clustering": {"rho": 1e308}}'),
        ("epsilon 1e-320", '{"clustering": {"epsilon": 1e-320}}'),
        ("action high 1e7", '{"action": {"low": 0, "high": 1e7, "step": 1}}'),
        ("action high 1e9", '{"action": {"low": 0, "high": 1e9, "step": 1}}'),
        ("action step 1e-300", '{"action": {"low": -1, "high": 1, "step": 1e-300}}'),
        ("action low -Infinity", '{"action": {"low": -Infinity, "high": 1, "step": 0.5}}'),
        (
            "observation 2000 names",
            json.dumps(
                {
                    "observation": {
                        "names": [f"x{i}" for i in range(2000)],
                        "low": [0] * 2000,
                        "high": [1] * 2000,
                        "knee": [],
                    }
                }
            ),
        ),
        (
            "observation high 1e308",
            '{"observation": {"names": ["x"], "low": [0], "high": [1e308], "knee": []}}',
        ),
        ("max_states 1e9", '{"limits": {"max_states": 1000000000}}'),
        ("max_streams 0", '{"limits": {"max_streams": 0}}'),
        ("horizon 1e6", '{"reviser": {"horizon": 1000000}}'),
        ("activate_after 2**70", '{"reviser": {"activate_after_episodes": ' + str(2**70) + "}}"),
        ("criteria []", '{"criteria": []}'),
        (
            "criteria 1000",
            json.dumps(
                {"criteria": [{"name": f"c{i}", "direction": "increase"} for i in range(1000)]}
            ),
        ),
        ("learning_rate 1", '{"transitions": {"learning_rate": 1}}'),
        ("prior 1e308", '{"transitions": {"prior": 1e308}}'),
        ("belief_top_k 1e6", '{"limits": {"belief_top_k": 1000000}}'),
        ("config version 99", '{"version": 99}'),
    ]
    for i, (label, config) in enumerate(hostile):
        name = f"cfg-{i}"
        yield post(
            "configs", label, "/models", f'{{"name": "{name}", "config": {config}}}', then=name
        )


@battery("snapshots")
def snapshots(client: httpx.Client) -> Iterator[Probe]:
    """Issue #69, item 4: a restored snapshot keeps every invariant. Numeric leaves of the
    default model's exact state set to hostile values, one at a time (seeded)."""
    exact = client.get("/models/default", params={"tpm": "none"}).json()["exact"]
    leaves = list(_numeric_leaves(exact, ()))
    rng = np.random.default_rng(SEED)
    values = [10**7, -1, 2**62, 0, 1e308, 10**30]
    for n, i in enumerate(rng.choice(len(leaves), size=min(60, len(leaves)), replace=False)):
        path, _ = leaves[int(i)]
        value = values[n % len(values)]
        document = json.loads(json.dumps(exact))
        _set(document, path, value)
        name = f"snap-{n}"
        yield post(
            "snapshots",
            f"{'.'.join(map(str, path))}={value}",
            f"/models/{name}",
            json.dumps({"exact": document}),
            then=name,
            method="PUT",
        )
    config = json.loads(json.dumps(exact))
    config.get("config", {}).pop("clustering", None)
    yield post(
        "snapshots",
        "config without clustering",
        "/models/snap-cfg",
        json.dumps({"exact": config}),
        then="snap-cfg",
        method="PUT",
    )


@battery("uploads")
def uploads(client: httpx.Client) -> Iterator[Probe]:
    """Issue #69, item 5: archive members the format does not name are refused unread."""
    blob = client.get("/models/default", params={"format": "npz"}).content
    for label, member, size in (
        ("an unnamed member of 32 MiB of zeros", "extra.npy", 2**25),
        ("an unnamed member of 1 KiB", "colour.npy", 1024),
    ):
        out = io.BytesIO()
        with (
            zipfile.ZipFile(io.BytesIO(blob)) as source,
            zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as target,
        ):
            for item in source.infolist():
                target.writestr(item, source.read(item))
            target.writestr(member, bytes(size))
        yield post(
            "uploads",
            label,
            "/models/upload-probe",
            out.getvalue(),
            then="upload-probe",
            method="PUT",
            content_type="application/x-npz",
        )
    yield post(
        "uploads",
        "truncated archive",
        "/models/upload-probe",
        blob[: len(blob) // 2],
        then="upload-probe",
        method="PUT",
        content_type="application/x-npz",
    )


def _numeric_leaves(node: Any, path: tuple[Any, ...]) -> Iterator[tuple[tuple[Any, ...], Any]]:
    if isinstance(node, dict):
        for key, value in node.items():
            yield from _numeric_leaves(value, (*path, key))
    elif isinstance(node, list):
        for i, value in enumerate(node[:4]):
            yield from _numeric_leaves(value, (*path, i))
    elif isinstance(node, int | float) and not isinstance(node, bool):
        yield path, node


def _set(node: Any, path: tuple[Any, ...], value: Any) -> None:
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value


class Target:
    """The server under test and what its models look like."""

    def __init__(self, url: str) -> None:
        self.url = url
        self.client = httpx.Client(base_url=url, timeout=30)
        self.address = ("127.0.0.1", int(url.rsplit(":", 1)[1]))

    def fingerprint(self) -> str:
        """Every model's exact state and the list of models, hashed."""
        digest = hashlib.sha256()
        names = sorted(m["name"] for m in self.client.get("/models").json()["models"])
        for name in names:
            r = self.client.get(f"/models/{name}", params={"tpm": "none"})
            digest.update(name.encode() + str(r.status_code).encode() + r.content)
        return digest.hexdigest()

    def send(self, probe: Probe) -> tuple[str, bool]:
        """The answer in a few words, and whether it was a server error."""
        if probe.http is not None:
            method, path, body, headers = probe.http
            try:
                r = self.client.request(method, path, content=body, headers=headers)
            except httpx.TransportError as error:
                return f"dropped ({type(error).__name__})", True
            code = _code(r.content)
            return f"{r.status_code} {code}", r.status_code >= 500
        if probe.raw is not None:
            return self._raw(probe.raw)
        assert probe.ws is not None
        return self._ws(probe.ws)

    def _raw(self, data: bytes) -> tuple[str, bool]:
        answer = b""
        with socket.create_connection(self.address, timeout=5) as s:
            try:
                s.sendall(data)
                while chunk := s.recv(65536):  # until the answer is whole, or the close
                    answer += chunk
                    head, _, body = answer.partition(b"\r\n\r\n")
                    length = re.search(rb"content-length: *(\d+)", head, re.IGNORECASE)
                    if (
                        length is not None
                        and len(body) >= int(length[1])
                        or body.endswith(b"0\r\n\r\n")
                    ):
                        break
            except OSError as error:
                return f"dropped ({error})", True
        if not answer:
            return "closed without an answer", True
        status = answer.split(b" ", 2)[1].decode(errors="replace")
        head, _, body = answer.partition(b"\r\n\r\n")
        if b"transfer-encoding: chunked" in head.lower():
            body = _dechunk(body)
        return f"{status} {_code(body)}", status.startswith("5")

    def _ws(self, frame: str | bytes) -> tuple[str, bool]:
        ws = websocket.create_connection(self.url.replace("http", "ws") + "/ws", timeout=20)
        try:
            if isinstance(frame, bytes):
                ws.send_binary(frame)
            else:
                ws.send(frame)
            opcode, data = ws.recv_data(control_frame=True)
        except (OSError, websocket.WebSocketException) as error:
            return f"dropped ({type(error).__name__})", True
        finally:
            ws.close()
        if opcode == websocket.ABNF.OPCODE_CLOSE:
            return f"ws close {int.from_bytes(data[:2], 'big')}", False
        reply = json.loads(data)
        if "error" not in reply:
            return "ws decision", False
        return f"ws {reply['error']['code']}", reply["error"]["code"] == "internal"

    def after(self, name: str) -> str | None:
        """A step and a read of a model a probe made: the first server error, if any."""
        for method, path, body in (
            ("POST", f"/models/{name}/revise", STEP),
            ("GET", f"/models/{name}", None),
            ("GET", f"/models/{name}?format=npz", None),
            ("GET", "/readyz", None),
        ):
            r = self.client.request(method, path, json=body)
            if r.status_code >= 500 and not (path == "/readyz" and r.status_code == 503):
                return f"then {method} {path}: {r.status_code} {_code(r.content)}"
        self.client.delete(f"/models/{name}")
        return None


def _dechunk(body: bytes) -> bytes:
    out = b""
    while body:
        size, _, rest = body.partition(b"\r\n")
        length = int(size, 16)
        out, body = out + rest[:length], rest[length + 2 :]
        if not length:
            break
    return out


def _code(body: bytes) -> str:
    try:
        return str(json.loads(body)["error"]["code"])
    except (ValueError, KeyError, TypeError):
        return "(no error body)" if body else ""


def half_sent(target: Target, count: int) -> int:
    """Open ``count`` sockets that send a request line and one header, then stop; a normal
    request is served meanwhile. Returns how many are still open after twice the time-out."""
    sockets = []
    for _ in range(count):
        s = socket.create_connection(target.address)
        s.sendall(b"POST /revise HTTP/1.1\r\nHost: shield\r\n")
        sockets.append(s)
    assert target.client.get("/healthz").status_code == 200
    deadline = time.monotonic() + 2 * TIMEOUT + 1
    still_open = 0
    for s in sockets:
        s.settimeout(max(0.01, deadline - time.monotonic()))
        try:
            while s.recv(65536):
                pass
        except TimeoutError:
            still_open += 1
        except OSError:
            pass
        s.close()
    return still_open


def run(target: Target, only: list[str], half_sent_count: int) -> Report:
    report = Report()
    before = target.fingerprint()
    for name in (b for b in only if b in BATTERIES):
        for probe in BATTERIES[name](target.client):
            answer, server_error = target.send(probe)
            outcome = Outcome(probe, answer, server_error)
            accepted = answer[:1] == "2" or answer == "ws decision"
            if accepted and probe.then is not None:
                trouble = target.after(probe.then)
                if trouble is not None:
                    outcome.answer += f"; {trouble}"
                    outcome.server_error = True
            now = target.fingerprint()
            outcome.changed = not accepted and now != before
            before = now
            report.outcomes.append(outcome)
    if "half-sent" in only:
        report.half_sent = half_sent_count
        report.half_sent_open = half_sent(target, half_sent_count)
    return report


def start(data_dir: Path) -> tuple[subprocess.Popen[bytes], str]:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    command = [
        sys.executable,
        "-m",
        "app",
        "serve",
        "--host",
        "127.0.0.1",
        "--port",
        str(port),
        "--data-dir",
        str(data_dir),
        "--max-body-bytes",
        str(BODY_LIMIT),
        "--max-batch",
        str(MAX_BATCH),
        "--header-timeout",
        str(TIMEOUT),
        "--body-timeout",
        str(TIMEOUT),
        "--log-level",
        "error",
    ]
    process = subprocess.Popen(
        command,
        cwd=Path(__file__).resolve().parents[1],
        env={**os.environ, "PYTHONPATH": str(Path(__file__).parents[1])},
    )
    url = f"http://127.0.0.1:{port}"
    for _ in range(1200):
        if process.poll() is not None:
            raise RuntimeError("the server exited")
        try:
            if httpx.get(url + "/readyz").status_code == 200:
                return process, url
        except httpx.TransportError:
            time.sleep(0.1)
    process.kill()
    raise RuntimeError("the server did not start")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument(
        "--only", nargs="+", choices=[*BATTERIES, "half-sent"], default=[*BATTERIES, "half-sent"]
    )
    parser.add_argument("--half-sent", type=int, default=200, help="half-sent sockets")
    parser.add_argument("--json", type=Path, help="also write the results here")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        process, url = start(Path(tmp) / "data")
        started = time.monotonic()
        try:
            target = Target(url)
            for _ in range(30):  # a model with states and counts to change
                target.client.post("/revise", json=STEP)
            report = run(target, args.only, args.half_sent)
        finally:
            process.terminate()
            process.wait(10)
    summary = report.summary() | {"seconds": round(time.monotonic() - started, 1)}
    print(
        f"probes sent: {summary['probes']} ({summary['half_sent']} of them half-sent sockets)"
        f" in {summary['seconds']} s"
    )
    print(f"5xx answers (goal 0): {summary['5xx']}")
    print(f"refused probes that changed a model (goal 0): {summary['changed']}")
    print(
        f"half-sent sockets open after {2 * TIMEOUT + 1:g} s (goal 0): {summary['half_sent_open']}"
    )
    for name, counts in summary["batteries"].items():
        print(
            f"  {name:10s} {counts.get('probes', 0):4d} probes, {counts.get('5xx', 0)} 5xx, "
            f"{counts.get('changed', 0)} changed"
        )
    for line in summary["failures"]:
        print("  FAIL", line)
    if args.json:
        args.json.write_text(json.dumps(summary, indent=1) + "\n")


if __name__ == "__main__":
    main()
