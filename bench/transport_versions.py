"""The shield clients of another commit beside this checkout's, against one service: did a
change make a request cheaper?

The other commit's ``client/shield`` package is loaded as a package of its own
(``bench/versions.py``). One service (``bench/service_app.py``, pinned to core 0 as in
``bench/service.py``) holds for each commit the same models, of 10 states built as in the core
benchmark, so that every step is learned and its proposal inspected. In each round the two
commits' clients take turns request by request (who goes first swapped every round), with
the same steps, so that a drift of the machine's speed falls on both: a block of single steps
through ``ShieldClient.revise`` (the HTTP transport of one run), then a block of requests
through ``BatchShield.revise_many``, each a step of ten models (a lockstep round of the
protocol). Reported per request: the medians over rounds, the median of the rounds'
ratios, and whether both commits got the same decisions.

    python bench/transport_versions.py 636ea5f --json bench/results/transport_versions_636ea5f.json
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from types import ModuleType
from typing import Any

import httpx

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import client.shield as this_shield  # noqa: E402
from app.service import codec  # noqa: E402
from bench.core_step import build, steps, variant  # noqa: E402
from bench.service import SEED, free_port, start  # noqa: E402
from bench.versions import load_package, paired, table_row  # noqa: E402

MODELS = 10  # a lockstep round: a step of each run's model


def upload(base: str, names: list[str]) -> None:
    blob = codec.to_npz(variant(build(10), "inspect"))
    with httpx.Client(base_url=base, timeout=60) as admin:
        for name in names:
            response = admin.put(
                f"/models/{name}", content=blob, headers={"content-type": "application/x-npz"}
            )
            response.raise_for_status()


def single(shield: ModuleType, base: str, who: str) -> Callable[[int, int], list[Any]]:
    """One client for every round: each call gives a block's single-step requests."""
    client = shield.ShieldClient(base, model=f"{who}-single")
    return lambda block, seed: [
        lambda z=z, a=a: client.revise(z, a, stream="bench")
        for z, a in steps(block, seed, "inspect")
    ]


def batch(shield: ModuleType, base: str, who: str) -> Callable[[int, int], list[Any]]:
    """One carrier for every round: each call gives a block's batch requests."""
    carrier = shield.BatchShield(base)
    body = shield.remote.step_body

    def block_of(block: int, seed: int) -> list[Callable[[], Any]]:
        work = [steps(block, seed + 1000 * k, "inspect") for k in range(MODELS)]

        def request(i: int) -> Callable[[], Any]:
            return lambda: carrier.revise_many(
                [(f"{who}-{k}", body(*work[k][i], stream="bench")) for k in range(MODELS)]
            )

        return [request(i) for i in range(block)]

    return block_of


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("commit", help="the commit whose clients are the baseline")
    parser.add_argument("--rounds", type=int, default=9)
    parser.add_argument("--requests", type=int, default=300, help="single steps per block")
    parser.add_argument("--batches", type=int, default=100, help="batch requests per block")
    parser.add_argument("--json", help="also write the results here")
    args = parser.parse_args()

    port = free_port()
    server = start(port)
    base = f"http://127.0.0.1:{port}"
    kinds = {
        "one step a request (ShieldClient.revise)": (single, args.requests),
        f"a step of {MODELS} models a request (BatchShield.revise_many)": (batch, args.batches),
    }
    try:
        with tempfile.TemporaryDirectory() as directory:
            clients = {
                "other": load_package(args.commit, "client/shield", Path(directory)),
                "this": this_shield,
            }
            upload(base, [f"{who}-{m}" for who in clients for m in ["single", *range(MODELS)]])
            times: dict[str, dict[str, list[float]]] = {k: {"other": [], "this": []} for k in kinds}
            decisions: dict[str, dict[str, list[Any]]] = {
                k: {"other": [], "this": []} for k in kinds
            }
            requests = {
                kind: {who: make(clients[who], base, who) for who in clients}
                for kind, (make, _) in kinds.items()
            }
            for r in range(args.rounds):
                order = ("other", "this") if r % 2 == 0 else ("this", "other")
                for kind, (_, size) in kinds.items():
                    calls = {who: requests[kind][who](size, SEED + r) for who in order}
                    spent = dict.fromkeys(order, 0.0)
                    for i in range(size):  # request by request: a drift falls on both
                        for who in order:
                            start_time = time.perf_counter()
                            decisions[kind][who].append(calls[who][i]())
                            spent[who] += time.perf_counter() - start_time
                    for who in order:
                        times[kind][who].append(spent[who] / size)
    finally:
        server.kill()

    results: dict[str, Any] = {
        "machine": platform.machine(),
        "processor": platform.processor(),
        "python": platform.python_version(),
        "httpx": httpx.__version__,
        "baseline": args.commit,
        "rounds": args.rounds,
        "requests": args.requests,
        "batches": args.batches,
        "kinds": {},
    }
    print(
        f"\n{args.rounds} rounds; seed {SEED}; models of 10 states; server pinned to core 0; "
        f"httpx {httpx.__version__}\n"
    )
    print(
        f"| requests | {args.commit} (ms a request) | this checkout | speed-up (paired) "
        f"| same decisions |"
    )
    print("|---|---:|---:|---:|---|")
    for kind, t in times.items():
        same = decisions[kind]["other"] == decisions[kind]["this"]
        row = {**paired(t["other"], t["this"], unit=1e3), "same": same}
        results["kinds"][kind] = row
        print(table_row(kind, row, same))
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()
