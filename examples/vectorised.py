"""Four copies of CarFollowing-v0 in an SB3 vectorised environment, one shield for all.

Each copy's wrapper writes a stream of its own into the shared model, so their steps never
interleave; the model learns from all four. (With ``SubprocVecEnv`` every process would hold
its own in-process shield: share one model through the service instead, see
``remote_service.py``.) Prints progress every 30 s, then the shared model's counts. About a
minute on a 2-core machine as written.

    .venv/bin/pip install -e ".[client,sb3]"
    .venv/bin/python examples/vectorised.py [--steps 4000]
"""

from __future__ import annotations

import argparse
from functools import partial

import torch
from stable_baselines3 import TD3
from stable_baselines3.common.env_util import make_vec_env

from app.core import compiled
from client.shield import LocalShield, ShieldWrapper
from client.shield.sb3 import AppliedActionReplayBuffer, Failures
from client.sim import CarFollowingEnv

say = partial(print, flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=4000, help="steps of all copies together")
    args = parser.parse_args()
    torch.set_num_threads(1)  # small networks: one thread is as fast and leaves a core free
    say("loading the shield's compiled core (a first run compiles it: a minute or two)")
    say(f"  ready in {compiled.warm().seconds:.0f} s")
    shield = LocalShield()  # the car-following defaults
    env = make_vec_env(
        CarFollowingEnv,
        n_envs=4,
        seed=0,
        wrapper_class=ShieldWrapper,
        wrapper_kwargs={"shield": shield},
    )
    model = TD3(
        "MlpPolicy",
        env,
        learning_starts=500,
        seed=0,
        device="cpu",
        replay_buffer_class=AppliedActionReplayBuffer,
    )
    say(f"TD3 for {args.steps} steps over 4 copies")
    model.learn(total_timesteps=args.steps, callback=Failures(report=lambda line: say(f"  {line}")))
    core = shield.shield
    say(
        f"one model, {len(core.streams)} open streams, {core.counters.steps} steps, "
        f"{core.n_states} states, {core.counters.episodes} episodes ended, "
        f"revisions {dict(core.counters.interventions)}"
    )
    env.close()


if __name__ == "__main__":
    main()
