"""Eight copies of CarFollowing-v0 in Gymnasium's vector API, one shield model for all.

``ShieldVectorWrapper`` stays in this process and gives every copy a stream of its own, so the
copies may step in worker processes (``vectorization_mode="async"``) and still share what the
shield learns. The controller is the aggressive IDM of the simulator, which brakes late and
crashes behind a hard-braking lead; the shield revises from its 50th episode on. Prints
progress every 30 s, then the model's counts.

    .venv/bin/pip install -e ".[client]"
    .venv/bin/python examples/gymnasium_vector.py [--steps 8000] [--mode async]
"""

from __future__ import annotations

import argparse
import time
from functools import partial

import gymnasium as gym
import numpy as np

from app.core import compiled
from client.agents.idm import PRESETS
from client.shield import ShieldVectorWrapper
from client.sim import CarFollowingEnv

EVERY_S = 30.0  # [s] between progress lines
say = partial(print, flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=8000)
    parser.add_argument("--mode", choices=["sync", "async"], default="sync")
    args = parser.parse_args()
    say("loading the shield's compiled core (a first run compiles it: a minute or two)")
    say(f"  ready in {compiled.warm().seconds:.0f} s")
    copies = gym.make_vec("client.sim:CarFollowing-v0", num_envs=8, vectorization_mode=args.mode)
    # the copies' own configuration (the car-following defaults), which worker processes
    # cannot hand over
    envs = ShieldVectorWrapper(copies, config=CarFollowingEnv().shield_config())
    controller = PRESETS["aggressive"]
    observations, _ = envs.reset(seed=0)
    failures: dict[str, int] = {}
    say(f"the aggressive IDM in 8 copies for {args.steps} vector steps")
    start = time.monotonic()
    next_report = start + EVERY_S
    for step in range(args.steps):
        actions = np.array([[controller.act(o)] for o in observations], dtype=np.float32)
        observations, _, _, _, info = envs.step(actions)
        for i in np.flatnonzero(info["_event"]):
            if info["event"][i]:
                failures[info["event"][i]] = failures.get(info["event"][i], 0) + 1
        if time.monotonic() >= next_report:
            next_report = time.monotonic() + EVERY_S
            say(
                f"  {step + 1}/{args.steps} steps, failures {failures}, "
                f"{time.monotonic() - start:.0f} s"
            )
    core = envs.shield.shield  # type: ignore[attr-defined]
    say(
        f"{envs.num_envs} copies, one model: {core.counters.steps} steps, {core.n_states} "
        f"states, {core.counters.episodes} episodes ended, failures {failures}, "
        f"revisions {dict(core.counters.interventions)}"
    )
    envs.close()


if __name__ == "__main__":
    main()
