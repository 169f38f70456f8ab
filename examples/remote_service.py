"""SB3 TD3 behind the shield service: the model lives in ``python -m app serve``, the learner
reaches it over one WebSocket session.

Give ``--url`` of a running service, or let the example start one on 127.0.0.1 (and stop it).
The model is created with the car-following defaults unless it exists.

    python examples/remote_service.py [--url http://127.0.0.1:8000] [--steps 3000]
"""

from __future__ import annotations

import argparse
import socket
import subprocess
import sys
import time
from contextlib import ExitStack

import gymnasium as gym
from stable_baselines3 import TD3

from client.shield import (
    ShieldAPIError,
    ShieldClient,
    ShieldSession,
    ShieldUnavailable,
    ShieldWrapper,
)
from client.shield.sb3 import AppliedActionReplayBuffer

MODEL = "td3-car"


def start_service(stack: ExitStack) -> str:
    """A service of our own on a free port of 127.0.0.1, stopped when ``stack`` closes."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    server = subprocess.Popen([sys.executable, "-m", "app", "serve", "--host", "127.0.0.1",
                               "--port", str(port), "--log-level", "warning"])
    stack.callback(server.wait)
    stack.callback(server.terminate)
    url = f"http://127.0.0.1:{port}"
    for _ in range(200):
        try:
            with ShieldClient(url) as client:
                client.health()
            return url
        except ShieldUnavailable:
            time.sleep(0.1)
    raise RuntimeError("the shield service did not start")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--url", default=None)
    parser.add_argument("--token", default=None)
    parser.add_argument("--steps", type=int, default=3000)
    args = parser.parse_args()
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
        model = TD3("MlpPolicy", env, learning_starts=500, seed=0,
                    replay_buffer_class=AppliedActionReplayBuffer)
        model.learn(total_timesteps=args.steps)
        env.close()  # ends the open episode's stream; the session is the stack's to close
        with ShieldClient(url, token=args.token) as admin:
            summary = next(m for m in admin.models() if m["name"] == MODEL)
        print(f"model {MODEL} at {url}: {summary}")


if __name__ == "__main__":
    main()
