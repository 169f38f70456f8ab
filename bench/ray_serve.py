"""The sharded service on Ray Serve against the plain service, same machine, same run.

Four servers, one after the other: ``python -m app serve`` (one process), and ``python -m
app serve-ray`` (a local Ray instance) with 1 shard, 2 shards, and 2 shards behind 2
ingresses. For each, on fresh models of the default configuration (each step learned and
decided on):

* the latency of one step (``POST /models/{name}/revise``, one client, one request at a time);
* steps a second with ``--clients`` clients at once, each stepping its own model, one step a
  request;
* steps a second with the same clients sending batches of ``--batch`` steps;
* the CPU time a step costs in each part of the server during those two (read from /proc:
  Serve's HTTP proxy, the ingress, the shards, the rest of Ray or the plain server), which
  says what one core of each part carries, however many machines there are;
* and, for scale, the ingress's own code alone: a batch request through its app in this
  process, its shard answering at once.

The clients run here (asyncio, one thread), the servers in other processes: on a 2-core
machine they share the cores. Reported: medians over rounds.

    python -m bench.ray_serve --rounds 3 --seconds 5
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import os
import platform
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import httpx


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


def step(t: int) -> dict[str, Any]:
    """Step ``t`` of a car following a lead smoothly (episodes of 200 steps)."""
    return {
        "observation": [
            30.0 + 10.0 * math.sin(t / 20),
            20.0 + 2.0 * math.sin(t / 30),
            20.0 + 2.0 * math.cos(t / 25),
        ],
        "action": math.sin(t / 10),
        "done": t % 200 == 199,
        "event": None,
    }


def start(command: list[str]) -> tuple[subprocess.Popen[bytes], str]:
    port = free_port()
    url = f"http://127.0.0.1:{port}"
    process = subprocess.Popen(
        [*command, "--host", "127.0.0.1", "--port", str(port)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    deadline = time.monotonic() + 180
    while time.monotonic() < deadline:
        try:
            if httpx.get(url + "/readyz", timeout=2).status_code == 200:
                return process, url
        except httpx.TransportError:
            time.sleep(0.2)
    os.killpg(process.pid, signal.SIGKILL)
    raise RuntimeError(f"{command} did not start")


def latency(url: str, name: str, count: int) -> float:
    """Median seconds of one step, one request at a time."""
    times = []
    with httpx.Client(base_url=url, timeout=60) as client:
        for t in range(count):
            began = time.perf_counter()
            client.post(f"/models/{name}/revise", json=step(t)).raise_for_status()
            times.append(time.perf_counter() - began)
    return statistics.median(times)


ROLES = {"proxy": "ProxyActor", "ingress": ":Ingress", "shards": ":shard-"}


def cpu_seconds(session: int) -> dict[str, float]:
    """CPU seconds so far of the processes of a session, by part (``ROLES``, else other)."""
    tick = os.sysconf("SC_CLK_TCK")
    used = dict.fromkeys([*ROLES, "other"], 0.0)
    for entry in Path("/proc").iterdir():
        try:
            stat = (entry / "stat").read_text().rsplit(")", 1)[1].split()
            command = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode()
        except (OSError, IndexError):
            continue  # not a process, or gone
        if int(stat[3]) == session:
            role = next((r for r, key in ROLES.items() if key in command), "other")
            used[role] += (int(stat[11]) + int(stat[12])) / tick
    return used


async def throughput(url: str, names: list[str], seconds: float, batch: int) -> tuple[int, float]:
    """Steps done and seconds taken with one client a model (batches of ``batch`` when > 1)."""
    done = 0
    stop_at = time.perf_counter() + seconds

    async def client_loop(client: httpx.AsyncClient, name: str) -> None:
        nonlocal done
        t = 0
        while time.perf_counter() < stop_at:
            if batch > 1:
                body = {"steps": [step(t + i) for i in range(batch)]}
                r = await client.post(f"/models/{name}/revise/batch", json=body)
            else:
                r = await client.post(f"/models/{name}/revise", json=step(t))
            r.raise_for_status()
            t += batch
            done += batch

    limits = httpx.Limits(max_connections=len(names))
    async with httpx.AsyncClient(base_url=url, timeout=120, limits=limits) as client:
        began = time.perf_counter()
        await asyncio.gather(*(client_loop(client, n) for n in names))
        return done, time.perf_counter() - began


def ingress_alone(batch: int, count: int = 2000) -> float:
    """Microseconds of a batch request through the ingress app, with no Ray and a shard
    that answers at once: what the ingress's own code costs."""
    from app.cluster import asgi
    from app.cluster.ingress import ingress_app
    from app.settings import Settings

    body = json.dumps({"steps": [step(t) for t in range(batch)]}).encode()
    reply = asgi.Reply(200, ((b"content-type", b"application/json"),), b"{}")

    async def call(shard: int, method: str, *args: Any) -> Any:
        return reply if method == "request" else None

    async def requests() -> float:
        app = ingress_app(Settings(), 2, call, None)  # type: ignore[arg-type]
        request = asgi.Request(
            "POST",
            "/models/bench-0/revise/batch",
            b"",
            ((b"content-type", b"application/json"),),
            body,
        )
        began = time.perf_counter()
        for _ in range(count):
            await asgi.call(app, request)
        return (time.perf_counter() - began) / count * 1e6

    return asyncio.run(requests())


def measure(command: list[str], args: argparse.Namespace) -> dict[str, float]:
    process, url = start(command)
    try:
        names = [f"bench-{i}" for i in range(args.clients)]
        for name in names:
            httpx.post(url + "/models", json={"name": name}, timeout=60).raise_for_status()
        rounds: dict[str, list[float]] = {
            "latency_ms": [],
            "steps_per_s": [],
            "batch_steps_per_s": [],
        }
        cpu: dict[str, float] = {}
        steps_done = 0
        for _ in range(args.rounds):
            rounds["latency_ms"].append(latency(url, names[0], args.requests) * 1e3)
            for key, batch in (("steps_per_s", 1), ("batch_steps_per_s", args.batch)):
                before = cpu_seconds(process.pid)
                done, seconds = asyncio.run(throughput(url, names, args.seconds, batch))
                rounds[key].append(done / seconds)
                if batch > 1:  # CPU a step in batches: what a part's core carries at best
                    after = cpu_seconds(process.pid)
                    cpu = {k: cpu.get(k, 0.0) + after[k] - before[k] for k in after}
                    steps_done += done
        result = {key: statistics.median(values) for key, values in rounds.items()}
        return result | {f"cpu_us_{k}": v / steps_done * 1e6 for k, v in cpu.items()}
    finally:
        process.send_signal(signal.SIGTERM)
        try:
            process.wait(60)
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGKILL)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--seconds", type=float, default=5.0)
    parser.add_argument("--requests", type=int, default=300)
    parser.add_argument("--clients", type=int, default=8)
    parser.add_argument("--batch", type=int, default=64)
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    python = [sys.executable, "-m", "app"]
    results = {}
    with tempfile.TemporaryDirectory() as scratch:
        servers = {
            "plain": [*python, "serve"],
            "ray, 1 shard": [*python, "serve-ray", "--shards", "1", "--data-dir", f"{scratch}/one"],
            "ray, 2 shards": [
                *python,
                "serve-ray",
                "--shards",
                "2",
                "--data-dir",
                f"{scratch}/two",
            ],
            "ray, 2 shards, 2 ingresses": [
                *python,
                "serve-ray",
                "--shards",
                "2",
                "--ingresses",
                "2",
                "--data-dir",
                f"{scratch}/three",
            ],
        }
        for label, command in servers.items():
            results[label] = measure(command, args)
            print(label, {k: round(v, 2) for k, v in results[label].items()}, flush=True)
    alone = statistics.median(ingress_alone(args.batch) for _ in range(args.rounds))
    plain = results["plain"]
    print(
        f"\nthe ingress's own code, in process: {alone:.0f} us a batch request "
        f"({alone / args.batch:.1f} us a step)"
    )
    print(
        f"\n{os.cpu_count()} cores ({platform.processor() or platform.machine()}); "
        f"{args.clients} clients, batches of {args.batch}; medians of {args.rounds} rounds\n"
    )
    print(
        "| server | step latency (ms) | extra over plain (ms) | steps/s, one a request "
        "| steps/s, batches | CPU us a batched step: proxy / ingress / shards / other |"
    )
    print("|---|---:|---:|---:|---:|---|")
    for label, r in results.items():
        cpu = " / ".join(f"{r[f'cpu_us_{k}']:.0f}" for k in [*ROLES, "other"])
        print(
            f"| {label} | {r['latency_ms']:.2f} | {r['latency_ms'] - plain['latency_ms']:.2f} "
            f"| {r['steps_per_s']:.0f} | {r['batch_steps_per_s']:.0f} | {cpu} |"
        )
    if args.out is not None:
        args.out.write_text(
            json.dumps(
                {
                    "args": vars(args) | {"out": str(args.out)},
                    "results": results,
                    "ingress_alone_us": alone,
                },
                indent=1,
            )
        )


if __name__ == "__main__":
    main()
