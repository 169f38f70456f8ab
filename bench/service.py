"""Latency and throughput of the shield service against floors of the same app, same run.

The server runs in its own process pinned to one core (``taskset -c 0`` when available); the
client runs here. For default models (the risk reviser) of 10 and 1000 states (built by
``bench/step_cost.py``, loaded with PUT as ``.npz``; each step learned and its proposal
decided on):

* ``POST /models/{name}/revise`` with an httpx keep-alive client, against ``POST /bench/noop``
  (the same pydantic body in, a small JSON out);
* a WebSocket step on ``/models/{name}/ws``, against a WebSocket echo of the same frames;
* the batch route, in steps per second.

Reported: medians over rounds of p50 and p99 latency and of sequential throughput.

    python bench/service.py --rounds 5 --requests 500
"""

from __future__ import annotations

import argparse
import json
import platform
import shutil
import socket
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import websocket

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from app.service import codec  # noqa: E402
from bench.step_cost import build, steps  # noqa: E402

SEED = 0


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


def start(port: int, *options: str) -> subprocess.Popen[bytes]:
    command = [sys.executable, str(Path(__file__).with_name("service_app.py")), str(port), *options]
    if shutil.which("taskset"):
        command = ["taskset", "-c", "0", *command]
    process = subprocess.Popen(command)
    for _ in range(200):
        try:
            if httpx.get(f"http://127.0.0.1:{port}/readyz").status_code == 200:
                return process
        except httpx.TransportError:
            time.sleep(0.05)
    process.kill()
    raise RuntimeError("server did not start")


def bodies(count: int, seed: int) -> list[str]:
    return [
        json.dumps({"observation": z, "action": a, "stream": "bench"})
        for z, a in steps(count, seed, "keep")
    ]


def http_round(client: httpx.Client, path: str, payloads: list[str]) -> list[float]:
    headers = {"content-type": "application/json"}
    times = []
    for body in payloads:
        start = time.perf_counter()
        response = client.post(path, content=body, headers=headers)
        times.append(time.perf_counter() - start)
        assert response.status_code == 200, response.text
    return times


def ws_round(url: str, payloads: list[str]) -> list[float]:
    """The client library of ``client.shield.ShieldSession``, so the floor is the product's."""
    times = []
    ws = websocket.create_connection(url, skip_utf8_validation=True)
    try:
        for body in payloads:
            start = time.perf_counter()
            ws.send(body)
            reply = ws.recv()
            times.append(time.perf_counter() - start)
            assert '"error"' not in reply[:10], reply
    finally:
        ws.close()
    return times


def summarise(rounds: list[list[float]]) -> dict[str, float]:
    return {
        "p50_us": statistics.median(float(np.percentile(r, 50)) for r in rounds) * 1e6,
        "p99_us": statistics.median(float(np.percentile(r, 99)) for r in rounds) * 1e6,
        "per_s": statistics.median(len(r) / sum(r) for r in rounds),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--requests", type=int, default=500)
    parser.add_argument("--batch", type=int, default=1024)
    parser.add_argument("--json", help="also write the results here")
    args = parser.parse_args()

    port = free_port()
    server = start(port)
    base = f"http://127.0.0.1:{port}"
    results: dict[str, Any] = {}
    try:
        with httpx.Client(base_url=base, timeout=60) as client:
            for n in (10, 1000):
                blob = codec.to_npz(build(n).snapshot())
                name = f"s{n}"
                r = client.put(
                    f"/models/{name}", content=blob, headers={"content-type": "application/x-npz"}
                )
                assert r.status_code == 200, r.text
                rounds: dict[str, list[list[float]]] = {
                    "noop": [],
                    "revise": [],
                    "echo": [],
                    "ws": [],
                    "batch": [],
                }
                for i in range(args.rounds):
                    payloads = bodies(args.requests, SEED + i)
                    rounds["noop"].append(http_round(client, "/bench/noop", payloads))
                    rounds["revise"].append(http_round(client, f"/models/{name}/revise", payloads))
                    rounds["echo"].append(
                        ws_round(base.replace("http", "ws") + "/bench/echo", payloads)
                    )
                    rounds["ws"].append(
                        ws_round(base.replace("http", "ws") + f"/models/{name}/ws", payloads)
                    )
                    batch = {"steps": [json.loads(b) for b in bodies(args.batch, SEED + i)]}
                    start_t = time.perf_counter()
                    r = client.post(f"/models/{name}/revise/batch", json=batch)
                    elapsed = time.perf_counter() - start_t
                    assert r.status_code == 200, r.text
                    rounds["batch"].append([elapsed / args.batch] * args.batch)
                results[name] = {k: summarise(v) for k, v in rounds.items()}
                print(f"{name}: done", flush=True)
    finally:
        server.terminate()
        server.wait(10)

    pinned = "server pinned to core 0" if shutil.which("taskset") else "server not pinned"
    print(
        f"\nseed {SEED}; {args.rounds} rounds of {args.requests} sequential requests "
        f"(batch: {args.batch} steps); medians over rounds; {pinned}; "
        f"{platform.machine()}, Python {platform.python_version()}\n"
    )
    print("| states | route | p50 (us) | p99 (us) | per second | vs floor (p50) |")
    print("|---:|---|---:|---:|---:|---:|")
    for name, r in results.items():
        states = name[1:]
        rows = [
            ("no-op route (floor)", "noop", None),
            ("POST /revise", "revise", "noop"),
            ("WebSocket echo (floor)", "echo", None),
            ("WebSocket step", "ws", "echo"),
            ("batch route, per step", "batch", None),
        ]
        for label, key, floor in rows:
            ratio = f"{r[key]['p50_us'] / r[floor]['p50_us']:.2f}x" if floor else ""
            print(
                f"| {states} | {label} | {r[key]['p50_us']:.0f} | {r[key]['p99_us']:.0f} "
                f"| {r[key]['per_s']:.0f} | {ratio} |"
            )
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()
