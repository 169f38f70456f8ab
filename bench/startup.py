"""Start-up of ``python -m app serve`` with the compiled core's cache warm: seconds from the
process start to the first 200 of ``/readyz``, against the floor of importing the app and
its dependencies in a fresh interpreter (the same run). Medians over rounds.

    python bench/startup.py --rounds 5
"""

from __future__ import annotations

import argparse
import platform
import socket
import statistics
import subprocess
import sys
import time

import httpx


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


def serve_seconds() -> float:
    port = free_port()
    start = time.perf_counter()
    process = subprocess.Popen(
        [sys.executable, "-m", "app", "serve", "--port", str(port)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        while True:
            try:
                if httpx.get(f"http://127.0.0.1:{port}/readyz").status_code == 200:
                    return time.perf_counter() - start
            except httpx.TransportError:
                time.sleep(0.01)
    finally:
        process.terminate()
        process.wait(10)


def import_seconds() -> float:
    start = time.perf_counter()
    subprocess.run(
        [sys.executable, "-c", "import app.main, app.core.compiled, uvicorn"], check=True
    )
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--rounds", type=int, default=5)
    args = parser.parse_args()
    subprocess.run([sys.executable, "-m", "app", "warm"], check=True, capture_output=True)
    serve = statistics.median(serve_seconds() for _ in range(args.rounds))
    floor = statistics.median(import_seconds() for _ in range(args.rounds))
    print(
        f"{args.rounds} rounds, medians; {platform.machine()}, Python {platform.python_version()}\n"
    )
    print("| start-up, cache warm | seconds | x import floor |")
    print("|---|---:|---:|")
    print(f"| import the app (floor) | {floor:.2f} | |")
    print(
        f"| `python -m app serve` to the first /readyz 200 | {serve:.2f} | {serve / floor:.2f}x |"
    )


if __name__ == "__main__":
    main()
