"""Four copies of CarFollowing-v0 in an SB3 vectorised environment, one shield for all.

Each copy's wrapper writes a stream of its own into the shared model, so their steps never
interleave; the model learns from all four. (With ``SubprocVecEnv`` every process would hold
its own in-process shield: share one model through the service instead, see
``remote_service.py``.)

    python examples/vectorised.py [--steps 4000]
"""

from __future__ import annotations

import argparse

from stable_baselines3 import TD3
from stable_baselines3.common.env_util import make_vec_env

from client.shield import LocalShield, ShieldWrapper
from client.shield.sb3 import AppliedActionReplayBuffer
from client.sim import CarFollowingEnv


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=4000)
    args = parser.parse_args()
    shield = LocalShield()  # the car-following defaults
    env = make_vec_env(CarFollowingEnv, n_envs=4, seed=0, wrapper_class=ShieldWrapper,
                       wrapper_kwargs={"shield": shield})
    model = TD3("MlpPolicy", env, learning_starts=500, seed=0,
                replay_buffer_class=AppliedActionReplayBuffer)
    model.learn(total_timesteps=args.steps)
    core = shield.shield
    print(f"one model, {len(core.streams)} open streams, {core.counters.steps} steps, "
          f"{core.n_states} states, {core.counters.episodes} episodes ended, "
          f"revisions {dict(core.counters.interventions)}")
    env.close()


if __name__ == "__main__":
    main()
