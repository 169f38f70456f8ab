"""Data-loss trials: a real server killed (SIGKILL) at random moments, one of its model's files
damaged, then restarted, fed and killed again; no step acknowledged after a recovery may be
lost, and no step sent again with its idempotency key may be applied twice (issue #69).

Each trial: ``python -m app serve --fsync always --snapshot-every 200`` on 127.0.0.1 with a
model for each kind of damage, each fed keyed steps by a client of its own until the server is
killed at a random moment; one file of each model is damaged (a torn, bit-flipped or
garbage-ended journal, a deleted journal, a damaged snapshot, a garbage ``config.json``); the
server restarts and each model is either repaired or set aside (quarantined, its files
untouched). A repaired model gets its unanswered step sent again with its key, then more keyed
steps until a second random kill, and after the last restart the unanswered step once more.
Counted, by kind of damage:

- acknowledged: steps answered after a recovery (the second phase);
- lost: of those, steps the model no longer holds after the last restart (goal 0);
- applied twice: steps sent again with their key whose first send had been applied and
  that were applied once more (goal 0);
- cut by the damage: acknowledged steps of the first phase the damage itself destroyed (a
  journal's damaged last record), which no store can give back; reported, not a loss of the
  service's.

    python -m bench.durability --trials 5
"""

from __future__ import annotations

import argparse
import os
import random
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx

from client.shield import Retry, ShieldClient, ShieldUnavailable, new_key

SNAPSHOT_EVERY = 200  # [steps]


def _cut_40_bytes(model: Path) -> None:
    journal = model / "journal.log"
    journal.write_bytes(journal.read_bytes()[:-40])


def _flip_a_bit(model: Path) -> None:
    journal = model / "journal.log"
    data = bytearray(journal.read_bytes())
    if len(data) > 20:
        data[-20] ^= 0x04
    journal.write_bytes(bytes(data))


def _garbage_tail(model: Path) -> None:
    with open(model / "journal.log", "ab") as f:
        f.write(random.Random(0).randbytes(64).replace(b"\n", b"x") + b"\n")


def _delete_journal(model: Path) -> None:
    (model / "journal.log").unlink()


def _truncate_snapshot(model: Path) -> None:
    snapshot = model / "snapshot.npz"
    snapshot.write_bytes(snapshot.read_bytes()[: snapshot.stat().st_size // 2])


def _garbage_config(model: Path) -> None:
    (model / "config.json").write_bytes(b"\x00garbage{")


DAMAGE: dict[str, Callable[[Path], None]] = {
    "torn journal (last 40 bytes cut)": _cut_40_bytes,
    "bit-flipped journal (last record)": _flip_a_bit,
    "garbage journal tail (64 bytes)": _garbage_tail,
    "deleted journal": _delete_journal,
    "damaged snapshot (half cut)": _truncate_snapshot,
    "garbage config.json": _garbage_config,
}


@dataclass
class Outcome:
    """What one trial found."""

    recovery: str = ""  # "repaired" (served again) or "quarantined"
    acknowledged: int = 0
    lost: int = 0
    twice: int = 0
    cut: int = 0
    retried: int = 0  # unanswered steps sent again
    retried_applied: int = 0  # of them, those the model held already (the kill came between)


@dataclass
class Server:
    """A server process on a data directory."""

    data: Path
    url: str = ""
    process: subprocess.Popen[bytes] | None = None
    log: list[Path] = field(default_factory=list)

    def start(self) -> None:
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            port = s.getsockname()[1]
        self.url = f"http://127.0.0.1:{port}"
        out = self.data.parent / f"server-{port}.log"
        self.log.append(out)
        self.process = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "app",
                "serve",
                "--host",
                "127.0.0.1",
                "--port",
                str(port),
                "--data-dir",
                str(self.data),
                "--fsync",
                "always",
                "--snapshot-every",
                str(SNAPSHOT_EVERY),
            ],
            stdout=open(out, "wb"),
            stderr=subprocess.STDOUT,
        )
        deadline = time.monotonic() + 120  # a cold kernel cache compiles first
        while time.monotonic() < deadline:
            if self.process.poll() is not None:
                raise RuntimeError(f"server exited: {out.read_text()}")
            try:
                if httpx.get(self.url + "/readyz", timeout=1).status_code == 200:
                    return
            except httpx.TransportError:
                time.sleep(0.05)
        raise RuntimeError(f"server did not start: {out.read_text()}")

    def kill(self) -> None:
        assert self.process is not None
        self.process.send_signal(signal.SIGKILL)
        self.process.wait(10)

    def stop(self) -> None:
        if self.process is not None and self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)
            try:
                self.process.wait(10)
            except subprocess.TimeoutExpired:
                self.kill()

    def version(self, model: str) -> int:
        with ShieldClient(self.url) as shield:
            result: int = shield.snapshot(model, tpm="none")["model_version"]
            return result

    def quarantined(self) -> dict[str, str]:
        result: dict[str, str] = httpx.get(self.url + "/readyz", timeout=5).json()["quarantined"]
        return result


def _body(rng: random.Random, t: int) -> dict[str, Any]:
    done = t % 25 == 24
    return {
        "observation": [rng.uniform(0, 30), rng.uniform(0, 120), rng.uniform(0, 30)],
        "action": None if done else rng.uniform(-3, 2),
        "done": done,
        "idempotency_key": new_key(),
    }


@dataclass
class Drive:
    """One model's client until the kill: the versions of its answered steps, and the step
    it sent last if the answer did not come."""

    model: str
    seed: int
    versions: list[int] = field(default_factory=list)
    unanswered: dict[str, Any] | None = None

    def run(self, url: str, stop: threading.Event) -> None:
        rng = random.Random(self.seed)
        with ShieldClient(url, model=self.model, timeout=60) as shield:
            t = 0
            while not stop.is_set():
                body = _body(rng, t)
                self.unanswered = body
                try:
                    self.versions.append(shield.revise(**body).model_version)
                except ShieldUnavailable:
                    return
                self.unanswered = None
                t += 1


def _drive(server: Server, models: list[str], seed: int, seconds: float) -> dict[str, Drive]:
    """Keyed steps into every model at once until the server is killed after ``seconds``."""
    drives = {m: Drive(m, seed * 100 + i) for i, m in enumerate(models)}
    stop = threading.Event()
    threads = [threading.Thread(target=d.run, args=(server.url, stop)) for d in drives.values()]
    for thread in threads:
        thread.start()
    time.sleep(seconds)
    server.kill()
    stop.set()
    for thread in threads:
        thread.join()
    return drives


def _send_again(
    server: Server, model: str, body: dict[str, Any] | None, applied: bool, outcome: Outcome
) -> None:
    """Send the unanswered step again, as a client with ``retry`` does; count a second apply."""
    if body is None:
        return
    before = server.version(model)
    with ShieldClient(server.url, model=model, retry=Retry(attempts=10)) as shield:
        shield.revise(**body)
    outcome.retried += 1
    outcome.retried_applied += applied
    if applied and server.version(model) != before:
        outcome.twice += 1


def trial(seed: int, seconds: tuple[float, float] = (1.0, 3.0)) -> dict[str, Outcome]:
    """One trial: a model for each kind of damage in one server, each damaged after the first
    kill; the outcome of each kind."""
    rng = random.Random(seed)
    names = {kind: f"m{i}" for i, kind in enumerate(DAMAGE)}
    outcomes = {kind: Outcome() for kind in DAMAGE}
    with tempfile.TemporaryDirectory(prefix="efsm-durability-") as tmp:
        server = Server(Path(tmp) / "data")
        try:
            server.start()
            with ShieldClient(server.url) as admin:
                for name in names.values():
                    admin.create_model(name)
            first = _drive(server, list(names.values()), seed, rng.uniform(*seconds))
            files = {}
            for kind, name in names.items():
                model = server.data / "models" / name
                DAMAGE[kind](model)
                files[kind] = {p.name: p.read_bytes() for p in model.iterdir()}
            server.start()
            quarantined = server.quarantined()
            served = []
            for kind, name in names.items():
                outcome = outcomes[kind]
                model = server.data / "models" / name
                if name in quarantined:
                    outcome.recovery = "quarantined"
                    if {p.name: p.read_bytes() for p in model.iterdir()} != files[kind]:
                        raise AssertionError(f"{kind}: a quarantined model's files were changed")
                    continue
                outcome.recovery = "repaired"
                recovered = server.version(name)
                answered = len(first[name].versions)
                outcome.cut = max(0, answered - recovered)
                _send_again(server, name, first[name].unanswered, recovered > answered, outcome)
                served.append(kind)
            start = {kind: server.version(names[kind]) for kind in served}
            second = _drive(server, [names[k] for k in served], seed + 1, rng.uniform(*seconds))
            server.start()
            for kind in served:
                outcome, drive = outcomes[kind], second[names[kind]]
                n, final = len(drive.versions), server.version(names[kind])
                outcome.acknowledged = n
                outcome.lost = max(0, start[kind] + n - final)
                if sorted(drive.versions) != list(range(start[kind] + 1, start[kind] + n + 1)):
                    raise AssertionError(f"{kind}: answered versions are not consecutive")
                _send_again(server, names[kind], drive.unanswered, final > start[kind] + n, outcome)
        finally:
            server.stop()
    return outcomes


def run(
    trials: int, seed: int, seconds: tuple[float, float] = (1.0, 3.0)
) -> dict[str, list[Outcome]]:
    """``trials`` trials, each with every kind of damage; the outcomes by kind."""
    results: dict[str, list[Outcome]] = {kind: [] for kind in DAMAGE}
    for i in range(trials):
        for kind, outcome in trial(seed + i, seconds).items():
            results[kind].append(outcome)
    return results


def table(results: dict[str, list[Outcome]]) -> str:
    """The trials as a Markdown table, one row per kind of damage and one for all."""
    lines = [
        "| damage | trials | recovery | acknowledged after it | lost | sent again "
        "(applied before) | applied twice | cut by the damage |",
        "|---|---:|---|---:|---:|---:|---:|---:|",
    ]
    every = [o for outcomes in results.values() for o in outcomes]
    for kind, outcomes in [*results.items(), ("all", every)]:
        recoveries = sorted({o.recovery for o in outcomes})
        lines.append(
            f"| {kind} | {len(outcomes)} | {', '.join(recoveries)} | "
            f"{sum(o.acknowledged for o in outcomes)} | {sum(o.lost for o in outcomes)} | "
            f"{sum(o.retried for o in outcomes)} ({sum(o.retried_applied for o in outcomes)}) | "
            f"{sum(o.twice for o in outcomes)} | "
            f"{sum(o.cut for o in outcomes)} |"
        )
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--trials", type=int, default=5, help="trials (servers killed twice)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    started = time.monotonic()
    results = run(args.trials, args.seed)
    print(table(results))  # noqa: T201
    print(
        f"\n{sum(len(o) for o in results.values())} trials in "  # noqa: T201
        f"{time.monotonic() - started:.0f} s, seed {args.seed}, {os.cpu_count()} CPUs"
    )


if __name__ == "__main__":
    main()
