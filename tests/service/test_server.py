"""A real server process: kill -9 mid-stream, concurrent streams, the start command, clients."""

from __future__ import annotations

import asyncio
import os
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import httpx
import pytest

from app.core import Decision
from client.shield import (
    AsyncShieldClient,
    ShieldAPIError,
    ShieldClient,
    ShieldSession,
    ShieldUnavailable,
)
from tests.conftest import Server, free_port, start_server
from tests.utils import random_stream

pytestmark = pytest.mark.slow  # each test starts a real server


def test_nothing_acknowledged_is_lost_after_kill_9(live_server: Server) -> None:
    acknowledged = 0
    stop = threading.Event()
    # made before the clock starts: on a loaded machine making them took the three seconds
    steps = random_stream(5, 20_000)

    def drive() -> None:
        nonlocal acknowledged
        with ShieldClient(live_server.url) as shield:
            for z, a, done in steps:
                if stop.is_set():
                    return
                try:
                    shield.revise(z, None if done else a, done=done)
                except ShieldUnavailable:
                    return
                acknowledged += 1

    driver = threading.Thread(target=drive)
    driver.start()
    time.sleep(3.0)
    live_server.kill()  # SIGKILL while requests are in flight
    stop.set()
    driver.join()
    assert acknowledged > 50

    restarted = start_server(live_server.data_dir, "--fsync", "always")
    try:
        with ShieldClient(restarted.url) as shield:
            snapshot = shield.snapshot(exact=False, tpm="none")
        # every acknowledged step is there; at most the one in flight was applied unanswered
        assert acknowledged <= snapshot["model_version"] <= acknowledged + 1
    finally:
        restarted.stop()


def test_sixteen_concurrent_streams_learn_every_accepted_step(live_server: Server) -> None:
    accepted = [0] * 16

    def stream(i: int) -> None:
        with ShieldClient(live_server.url) as shield:
            for z, a, done in random_stream(i, 40):
                shield.revise(z, None if done else a, done=done, stream=f"car-{i}")
                accepted[i] += 1

    threads = [threading.Thread(target=stream, args=(i,)) for i in range(16)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    with ShieldClient(live_server.url) as shield:
        model = shield.snapshot(exact=False, tpm="none")
    assert model["steps"] == model["model_version"] == sum(accepted) == 640


def test_the_three_clients_agree_with_each_other(live_server: Server) -> None:
    steps = [(z, None if d else a, d) for z, a, d in random_stream(9, 100)]
    with ShieldClient(live_server.url) as admin:
        for name in ("via-http", "via-ws", "via-async"):
            admin.create_model(name, {"reviser": {"activate_after_episodes": 1}})
    with ShieldClient(live_server.url, model="via-http") as http:
        by_http = [http.revise(z, a, done=d, event="collision" if d else None) for z, a, d in steps]
        with pytest.raises(ShieldAPIError) as raised:
            http.revise([1.0], 0.0)
        assert (raised.value.status, raised.value.code, raised.value.field) == (
            422,
            "invalid_observation",
            "observation",
        )
    with ShieldSession(live_server.url, model="via-ws") as ws:
        by_ws = [ws.revise(z, a, done=d, event="collision" if d else None) for z, a, d in steps]

    async def run_async() -> list[Decision]:
        async with AsyncShieldClient(live_server.url, model="via-async") as shield:
            return [
                await shield.revise(z, a, done=d, event="collision" if d else None)
                for z, a, d in steps
            ]

    by_async = asyncio.run(run_async())
    assert by_http == by_ws == by_async  # typed records, field for field
    assert {"pass", "revised_safety"} & {d.reason for d in by_http}  # the reviser ran


def test_an_unreachable_shield_is_one_clear_error() -> None:
    with pytest.raises(ShieldUnavailable, match="unreachable"):
        ShieldClient(f"http://127.0.0.1:{free_port()}", timeout=1).health()
    with pytest.raises(ShieldUnavailable, match="unreachable"):
        ShieldSession(f"http://127.0.0.1:{free_port()}", timeout=1)


def test_a_shield_that_never_answers_a_step_times_out() -> None:
    with socket.create_server(("127.0.0.1", 0)) as silent:  # accepts, never answers
        url = f"http://127.0.0.1:{silent.getsockname()[1]}"
        started = time.monotonic()
        with ShieldClient(url, timeout=0.5) as shield:
            with pytest.raises(ShieldUnavailable, match="unreachable"):
                shield.revise([10.0, 50.0, 12.0], 0.5)
            with pytest.raises(ShieldUnavailable, match="unreachable"):
                shield.revise_batch([{"observation": [10.0, 50.0, 12.0], "model": "default"}])

        async def revise_async() -> None:
            async with AsyncShieldClient(url, timeout=0.5) as shield:
                await shield.revise([10.0, 50.0, 12.0], 0.5)

        with pytest.raises(ShieldUnavailable, match="unreachable"):
            asyncio.run(revise_async())
        assert time.monotonic() - started < 10


def test_the_clients_steps_carry_the_token(tmp_path: Path) -> None:
    server = start_server(tmp_path / "data", "--token", "secret")
    step: dict[str, Any] = {"observation": [10.0, 50.0, 12.0], "action": 0.5}
    try:
        with ShieldClient(server.url, token="secret") as shield:
            assert shield.revise(**step).model_version == 1
            assert shield.revise_batch([{**step, "model": "default"}])[0].model_version == 2
        with ShieldClient(server.url, token="wrong", model="default") as shield:
            for call in (lambda: shield.revise(**step), lambda: shield.revise_batch([step])):
                with pytest.raises(ShieldAPIError) as refused:
                    call()
                assert (refused.value.status, refused.value.code) == (401, "unauthorized")

        async def revise_async(token: str) -> Decision:
            async with AsyncShieldClient(server.url, token=token, model="default") as shield:
                return (await shield.revise_batch([step]))[0]

        assert asyncio.run(revise_async("secret")).model_version == 3
        with pytest.raises(ShieldAPIError, match="401 unauthorized"):
            asyncio.run(revise_async("wrong"))
    finally:
        server.stop()


def test_the_websocket_session_names_each_error_and_stays_in_step(tmp_path: Path) -> None:
    server = start_server(tmp_path / "data", "--token", "secret")
    try:
        with pytest.raises(ShieldAPIError) as refused:
            ShieldSession(server.url, token="wrong")
        assert (refused.value.status, refused.value.code) == (403, "unauthorized")
        with ShieldSession(server.url, token="secret", model="nobody") as missing:
            with pytest.raises(ShieldAPIError) as unknown:
                missing.revise([10.0, 50.0, 12.0], 0.5)
        assert (unknown.value.status, unknown.value.code) == (404, "unknown_model")
        with ShieldSession(server.url, token="secret") as session:
            first = session.revise([10.0, 50.0, 12.0], 0.5)
            with pytest.raises(ShieldAPIError) as bad:
                session.revise([10.0, 50.0], 0.5)
            assert (bad.value.status, bad.value.code, bad.value.field) == (
                422,
                "invalid_observation",
                "observation",
            )
            after = session.revise([10.0, 50.0, 12.0], 0.5)  # the session goes on
            assert after.model_version == first.model_version + 1
            server.kill()
            with pytest.raises(ShieldUnavailable, match="session lost"):
                session.revise([10.0, 50.0, 12.0], 0.5)
    finally:
        server.stop()


def test_a_websocket_frame_over_the_body_limit_is_refused_far_over_it_the_session_ends(
    tmp_path: Path,
) -> None:
    server = start_server(tmp_path / "data", "--max-body-bytes", "2048")
    try:
        with ShieldSession(server.url) as session:
            with pytest.raises(ShieldAPIError) as refused:
                session.revise([10.0, 50.0, 12.0], 0.5, stream="s" * 3000)
            assert (refused.value.status, refused.value.code) == (413, "too_large")
            assert session.revise([10.0, 50.0, 12.0], 0.5).model_version == 1
            with pytest.raises(ShieldUnavailable, match="session lost"):
                session.revise([10.0, 50.0, 12.0], 0.5, stream="s" * 5000)
    finally:
        server.stop()


def test_settings_come_from_the_environment_too(tmp_path: Path) -> None:
    server = start_server(tmp_path / "data", env={"EFSM_TOKEN": "from-env"})
    try:
        assert httpx.get(server.url + "/models").status_code == 401
        with ShieldClient(server.url, token="from-env") as shield:
            assert shield.models()[0]["name"] == "default"
    finally:
        server.stop()


def test_without_a_data_directory_the_server_says_so(tmp_path: Path) -> None:
    port = free_port()
    process = subprocess.Popen(
        [sys.executable, "-m", "app", "serve", "--port", str(port)],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
    )
    try:
        for _ in range(100):
            try:
                if httpx.get(f"http://127.0.0.1:{port}/readyz").status_code == 200:
                    break
            except httpx.TransportError:
                time.sleep(0.1)
    finally:
        process.terminate()
        output = process.communicate(timeout=10)[0].decode()
    assert "models live in memory only" in output
    assert "loading the compiled core" in output  # said before it listens ...
    assert "compiled core loaded from its cache" in output or "kernels in" in output


def test_the_container_command_runs_outside_docker(tmp_path: Path) -> None:
    """The Dockerfile's CMD and HEALTHCHECK, with the environment the image sets."""
    dockerfile = (Path(__file__).parents[2] / "Dockerfile").read_text()
    assert 'CMD ["python", "-m", "app", "serve"]' in dockerfile
    assert 'CMD ["python", "-m", "app.healthcheck"]' in dockerfile
    port = free_port()
    env = {
        **os.environ,
        "EFSM_HOST": "0.0.0.0",
        "EFSM_PORT": str(port),
        "EFSM_DATA_DIR": str(tmp_path / "data"),
    }
    probe = [sys.executable, "-m", "app.healthcheck"]
    assert subprocess.run(probe, env=env, timeout=10).returncode == 1  # nothing listens yet
    process = subprocess.Popen(
        [sys.executable, "-m", "app", "serve"],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        for _ in range(100):
            if subprocess.run(probe, env=env, timeout=10).returncode == 0:
                break
            time.sleep(0.1)
        else:
            pytest.fail("the health probe never passed")
        assert httpx.get(f"http://127.0.0.1:{port}/models").status_code == 200
        assert (tmp_path / "data/models/default/config.json").exists()
    finally:
        process.terminate()
        process.wait(10)


@pytest.mark.xdist_group("ray")  # timed: not beside a Ray instance (tests/cluster/test_ray.py)
def test_a_long_batch_on_one_model_does_not_stall_another(live_server: Server) -> None:
    with ShieldClient(live_server.url) as admin:
        admin.create_model("busy")
        admin.create_model("quiet")
    steps = [
        {"observation": z, "action": None if d else a, "done": d}
        for z, a, d in random_stream(3, 4096)
    ]
    finished = threading.Event()
    durations: list[float] = []

    def long_batch() -> None:  # four of the largest batches, one after the other
        with ShieldClient(live_server.url, model="busy", timeout=120) as busy:
            for _ in range(4):
                start = time.perf_counter()
                busy.revise_batch(steps)
                durations.append(time.perf_counter() - start)
        finished.set()

    worker = threading.Thread(target=long_batch)
    latencies = []
    with ShieldClient(live_server.url, model="quiet") as quiet:
        quiet.revise([10.0, 50.0, 12.0], 0.5)  # the connection and the model's first step
        worker.start()
        time.sleep(0.2)  # the batch is under way
        while not finished.is_set():
            start = time.perf_counter()
            quiet.revise([10.0, 50.0, 12.0], 0.5)
            latencies.append(time.perf_counter() - start)
    worker.join()
    # steps that waited for the batches would take the rest of a batch each: a handful would
    # finish, the typical one in about half a batch. On a loaded machine a tenth of the steps
    # can be slow for their own reasons (the GIL, the scheduler), so the check is the median.
    assert len(latencies) > 20, (len(latencies), durations)
    median = sorted(latencies)[len(latencies) // 2]
    assert median < min(durations) / 5, (median, latencies, durations)
