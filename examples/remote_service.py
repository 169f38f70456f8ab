"""SB3 TD3 behind the shield service: the model lives in ``python -m app serve``, the learner
reaches it over one WebSocket session.

Give ``--url`` of a running service, or let the example start one on 127.0.0.1 (and stop it;
its first start compiles the core, a minute or two). The model is created with the
car-following defaults unless it exists. Prints progress every 30 s, then the model's summary
as the service reports it. About two minutes on a 2-core machine as written.

    .venv/bin/pip install -e ".[client,service,sb3]"
    .venv/bin/python examples/remote_service.py [--url http://127.0.0.1:8000] [--steps 2000]
"""

from __future__ import annotations

import argparse
import socket
import subprocess
import sys
import time
from contextlib import ExitStack
from functools import partial

import gymnasium as gym
import torch
from stable_baselines3 import TD3

from client.shield import (
    ShieldAPIError,
    ShieldClient,
    ShieldSession,
    ShieldUnavailable,
    ShieldWrapper,
)
from client.shield.sb3 import AppliedActionReplayBuffer, Failures

MODEL = "td3-car"
START_S = 300.0  # [s] the longest a service of our own may take to answer (it compiles first)
say = partial(print, flush=True)


def start_service(stack: ExitStack) -> str:
    """A service of our own on a free port of 127.0.0.1, stopped when ``stack`` closes."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    server = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "app",
            "serve",
            "--host",
            "127.0.0.1",
            "--port",
            str(port),
            "--log-level",
            "warning",
        ]
    )
    stack.callback(server.wait)
    stack.callback(server.terminate)
    url = f"http://127.0.0.1:{port}"
    say(f"starting the shield service at {url} (a first start compiles its core: a minute or two)")
    start = time.monotonic()
    next_report = start + 30.0
    while time.monotonic() - start < START_S:
        if server.poll() is not None:
            raise RuntimeError(f"the shield service exited with status {server.returncode}")
        try:
            with ShieldClient(url) as client:
                client.health()
            say(f"  answering after {time.monotonic() - start:.0f} s")
            return url
        except ShieldUnavailable:
            time.sleep(0.5)
        if time.monotonic() >= next_report:
            next_report += 30.0
            say(f"  not answering yet after {time.monotonic() - start:.0f} s (compiling)")
    raise RuntimeError(f"the shield service did not answer within {START_S:.0f} s")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--url", default=None)
    parser.add_argument("--token", default=None)
    parser.add_argument("--steps", type=int, default=2000)
    args = parser.parse_args()
    torch.set_num_threads(1)  # small networks: one thread is as fast and leaves the service one
    with ExitStack() as stack:
        url = args.url or start_service(stack)
        with ShieldClient(url, token=args.token) as admin:
            try:
                admin.create_model(MODEL, {})
            except ShieldAPIError as error:
                if error.code != "model_exists":
                    raise
        shield = stack.enter_context(ShieldSession(url, token=args.token, model=MODEL))
        env = ShieldWrapper(gym.make("client.sim:CarFollowing-v0"), shield, stream="td3-0")
        model = TD3(
            "MlpPolicy",
            env,
            learning_starts=500,
            seed=0,
            device="cpu",
            replay_buffer_class=AppliedActionReplayBuffer,
        )
        say(f"TD3 for {args.steps} steps, each revised by the service")
        model.learn(
            total_timesteps=args.steps, callback=Failures(report=lambda line: say(f"  {line}"))
        )
        env.close()  # ends the open episode's stream; the session is the stack's to close
        with ShieldClient(url, token=args.token) as admin:
            summary = next(m for m in admin.models() if m["name"] == MODEL)
        say(f"model {MODEL} at {url}: {summary}")


if __name__ == "__main__":
    main()
