"""Where a WebSocket step of the service goes: the model's step inside the server, against the
same e-FSM steps in a plain loop and the WebSocket echo of the same app.

The server (``bench/service_app.py --timing``) runs pinned to core 0 and times every call of
``ModelRegistry.try_step``: validation, journal (none here: models in memory) and the e-FSM
step. A second process, pinned to the same core, runs the same steps through
``Shield.step`` (validation and the e-FSM step) on the same model in a loop. Default models
(the risk reviser) of 10 and 1000 states as in ``bench/service.py``; per round the WebSocket
echo, then the steps; medians over rounds of the per-step medians.

    python bench/service_split.py --rounds 5 --requests 500
"""

from __future__ import annotations

import argparse
import json
import platform
import shutil
import statistics
import subprocess
import sys
from pathlib import Path

import httpx

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from app.service import codec  # noqa: E402
from bench.service import SEED, bodies, free_port, start, ws_round  # noqa: E402
from bench.step_cost import build  # noqa: E402

LOOP = """
import json, statistics, sys, time
sys.path.insert(0, {root!r})
from app.core import Shield
from bench.step_cost import build, steps
snapshot = build({n}).snapshot()
out = []
for r in range({rounds}):
    shield = Shield.from_snapshot(snapshot)
    times = []
    for z, a in steps({requests}, {seed} + r, "keep"):
        start = time.perf_counter()
        shield.step(z, a, stream="bench")
        times.append(time.perf_counter() - start)
    out.append(statistics.median(times))
print(json.dumps(out))
"""


def loop_medians(n: int, rounds: int, requests: int) -> list[float]:
    """Per round, the median seconds of a step in a plain loop, pinned beside the server."""
    code = LOOP.format(
        root=str(Path(__file__).resolve().parents[1]),
        n=n,
        rounds=rounds,
        requests=requests,
        seed=SEED,
    )
    command = [sys.executable, "-c", code]
    if shutil.which("taskset"):
        command = ["taskset", "-c", "0", *command]
    result = subprocess.run(command, check=True, capture_output=True, text=True)
    medians: list[float] = json.loads(result.stdout)
    return medians


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--requests", type=int, default=500)
    args = parser.parse_args()

    port = free_port()
    server = start(port, "--timing")
    base = f"http://127.0.0.1:{port}"
    ws_base = base.replace("http", "ws")
    rows = []
    try:
        with httpx.Client(base_url=base, timeout=60) as client:
            for n in (10, 1000):
                blob = codec.to_npz(build(n).snapshot())
                echo, step, inside = [], [], []
                for i in range(args.rounds):
                    r = client.put(
                        f"/models/s{n}", content=blob, headers={"content-type": "application/x-npz"}
                    )
                    assert r.status_code == 200, r.text
                    payloads = bodies(args.requests, SEED + i)
                    echo.append(statistics.median(ws_round(ws_base + "/bench/echo", payloads)))
                    client.get("/bench/timing")  # drop the times of anything before
                    step.append(statistics.median(ws_round(ws_base + f"/models/s{n}/ws", payloads)))
                    inside.append(statistics.median(client.get("/bench/timing").json()))
                loop = loop_medians(n, args.rounds, args.requests)
                rows.append((n, *(statistics.median(v) * 1e6 for v in (echo, step, inside, loop))))
    finally:
        server.terminate()
        server.wait(10)

    pinned = "server pinned to core 0" if shutil.which("taskset") else "server not pinned"
    print(
        f"\nseed {SEED}; {args.rounds} rounds of {args.requests} WebSocket steps; medians "
        f"over rounds of per-step medians (us); {pinned}; {platform.machine()}, "
        f"Python {platform.python_version()}\n"
    )
    print(
        "| states | WebSocket echo | WebSocket step | model step in the server "
        "| rest of the step over the echo | the same steps in a loop |"
    )
    print("|---:|---:|---:|---:|---:|---:|")
    for n, echo_us, step_us, inside_us, loop_us in rows:
        print(
            f"| {n} | {echo_us:.0f} | {step_us:.0f} | {inside_us:.0f} "
            f"| {step_us - echo_us - inside_us:.0f} | {loop_us:.0f} |"
        )


if __name__ == "__main__":
    main()
