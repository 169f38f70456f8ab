"""Tuning and demonstration world for #68 on a public driving benchmark: Farama's highway-env
1.12.1, ``highway-v0``, with its ego car's acceleration as the one action.

The ego car drives on a four-lane highway among IDM/MOBIL cars (highway-env's own traffic),
steered along its lane by nobody (``ContinuousAction`` with ``longitudinal=True,
lateral=False``: the action in [-1, 1] is the acceleration, scaled to [-5, 5] m/s²). The
controller tracks 34 m/s and brakes fully only when the car ahead in its lane is within
``BRAKE_GAP`` (12 m, bumper to bumper) or ``BRAKE_TTC`` (2.5 s) of a collision, as #68 set it
up; it decides once a second (highway-env's default ``policy_frequency``), so it brakes late and
rear-ends a slower car ahead now and then: ``collision`` (``info["crashed"]``; fought by less
acceleration). The second world, ``highway_too_slow``, adds the failure a user adds next,
``too_slow``: the ego below ``TOO_SLOW`` (20 m/s; fought by more acceleration), which ends the
episode as a crash does.

The environment (``ENV_CONFIG``) is highway-v0's default but for what makes it cheap enough to
run hundreds of episodes on two cores, where the default takes 10-20 s an episode (50 cars
simulated at 15 Hz for 40 s): ``simulation_frequency`` 5 Hz and ``vehicles_count`` 15 (as
highway-fast-v0, whose other cars' mutual collision checks are kept here), and ``duration``
18 s; nothing is rendered (``offscreen_rendering``). The cars are placed ahead of the ego, and
the ego cannot leave its lane, so only the nearest few ever matter within 18 s. The duration
sets the crash share: the controller never settles behind a slower car (it returns to 34 m/s
after each braking), so it crashes sooner or later in most episodes: at the default 40 s in
85-90% of them. 18 s was chosen on seed 9 (40 episodes: 42% crashed within it) for the 39%
#68 reports, which states neither value; calibrated alone on seeds 0-2, 60 episodes each
(``python -m bench.worlds.highway``): ``highway`` 43% crashed (38, 55, 37% per seed), mean
speed 26.4 m/s (#68: 39%, 27.0 m/s); ``highway_too_slow`` 92% failed, 67% ``too_slow`` and
24% ``collision``, mean speed 30.2 m/s: the controller's braking comes in whole seconds of
5 m/s² (34, 29, 24, 19 m/s), so matching a car ahead at 20-24 m/s takes it below 20 m/s in
most episodes, and that ends them before a crash would. About 0.5 s an episode alone on one
shared core of the development machine.

The shield observes highway-env's default observation, ``Kinematics`` (the ego and the four
nearest cars ahead or beside it, sorted by distance; per car presence, x, y, vx, vy,
normalised and clipped to [-1, 1]; the ego's x and y absolute, its x clipped at 1 once
past 200 m, the others' relative to it; rows of cars not seen are zeros),
flattened to 25 numbers and declared over [-1, 1], as a new user writes it and as #68 ran it
(``config_for`` with ``low``/``high``, the space itself being ``Box(-inf, inf)``). A few
hand-picked features (the ego's speed, the gap to the car ahead and the closing speed) would
make the model's states sharper, but they are the designer's knowledge a new user lacks; the
flattened observation keeps #68's set-up.

The controller's task figure (``info["task"]``, per step; added by :class:`SpeedTask`, as is
``info["speed"]``) is the ego's shortfall below 34 m/s. highway-env lets braking carry the
ego's speed below zero (it reverses, down to -40 m/s); speed and shortfall are reported as
they are. A public world: a tuning and demonstration world, never a held-out one. Needs
``pip install 'efsm-shield[highway]'``; importing this module does not, running one of its
worlds does.
"""

from __future__ import annotations

import argparse
import importlib
import platform
import time
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
from gymnasium.spaces import Box

from app.core import ShieldConfig
from bench.worlds.harness import Spaces, World
from client.shield.spaces import config_for

TARGET_SPEED = 34.0  # [m/s] the speed the controller tracks
TOO_SLOW = 20.0  # [m/s] below it, ``too_slow``
BRAKE_GAP = 12.0  # [m] bumper to bumper: the controller brakes fully within it ...
BRAKE_TTC = 2.5  # [s] ... or within this time to collision
GAIN = 0.2  # the controller's speed gain [action per m/s]: 1 m/s² per m/s, deadbeat at 1 Hz
LENGTH = 5.0  # [m] highway-env's car length (Vehicle.LENGTH)
WIDTH = 2.0  # [m] its width (Vehicle.WIDTH): another car overlaps the ego's lane within it
LANES = 4  # highway-v0's default lanes_count
LANE_WIDTH = 4.0  # [m] AbstractLane.DEFAULT_WIDTH
MAX_SPEED = 40.0  # [m/s] Vehicle.MAX_SPEED, which sets the observation's scales
# the Kinematics observation's normalisation (KinematicObservation.normalize_obs): value over
# its range mapped to [-1, 1]
X_RANGE = 5.0 * MAX_SPEED  # [m]
Y_RANGE = LANE_WIDTH * LANES  # [m]
V_RANGE = 2.0 * MAX_SPEED  # [m/s]
CARS, FEATURES = 5, 5  # the observation's shape: cars x (presence, x, y, vx, vy)
MAX_STEPS = 18  # duration [s] x policy_frequency [Hz]

ENV_ID = "highway-v0"
ENV_CONFIG: dict[str, Any] = {
    "observation": {"type": "Kinematics"},  # the default: 5 cars x 5 features
    "action": {"type": "ContinuousAction", "longitudinal": True, "lateral": False},
    "policy_frequency": 1,  # the default
    "simulation_frequency": 5,  # 15 by default; 5 as highway-fast-v0
    "vehicles_count": 15,  # 50 by default; 20 in highway-fast-v0
    "duration": MAX_STEPS,  # [s] 40 by default
    "offscreen_rendering": True,
}
INSTALL = "pip install 'efsm-shield[highway]' (highway-env==1.12.1)"


class SpeedTask(gym.Wrapper[np.ndarray, np.ndarray, np.ndarray, np.ndarray]):
    """highway-env with the figures the harness reads: ``info["speed"]`` (the ego's speed,
    m/s), ``info["task"]`` (its shortfall below ``TARGET_SPEED``, lower better) and, where
    ``min_speed`` is given, ``info["too_slow"]``: the ego below it, which ends the episode
    (``terminated``) as a crash does. highway-env reports the speed but no task figure, and
    knows no failure but the crash."""

    def __init__(
        self, env: gym.Env[np.ndarray, np.ndarray], min_speed: float | None = None
    ) -> None:
        super().__init__(env)
        self.min_speed = min_speed

    def _figures(self, info: dict[str, Any]) -> dict[str, Any]:
        speed = float(self.env.unwrapped.vehicle.speed)  # type: ignore[attr-defined]
        info = {**info, "speed": speed, "task": max(0.0, TARGET_SPEED - speed)}
        if self.min_speed is not None:
            info["too_slow"] = speed < self.min_speed
        return info

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        observation, info = self.env.reset(seed=seed, options=options)
        return observation, self._figures(info)

    def step(
        self, action: np.ndarray
    ) -> tuple[np.ndarray, SupportsFloat, bool, bool, dict[str, Any]]:
        observation, reward, terminated, truncated, info = self.env.step(action)
        info = self._figures(info)
        return (
            observation,
            reward,
            bool(terminated or info.get("too_slow", False)),
            bool(truncated),
            info,
        )


def make_env(min_speed: float | None = None) -> SpeedTask:
    """``highway-v0`` as ``ENV_CONFIG`` sets it, wrapped in :class:`SpeedTask`; a clear error
    where highway-env is not installed (it is an optional extra)."""
    try:
        importlib.import_module("highway_env")  # registers highway-v0
    except ModuleNotFoundError as error:
        raise ModuleNotFoundError(f"the highway worlds need highway-env: {INSTALL}") from error
    env = gym.make(ENV_ID, config=ENV_CONFIG, disable_env_checker=True)
    return SpeedTask(env, min_speed)


def ahead(observation: np.ndarray) -> tuple[float, float] | None:
    """The car ahead in the ego's lane in a Kinematics observation (normalised, as highway-env
    gives it): its gap, bumper to bumper [m], and its closing speed (positive: the gap
    shrinks) [m/s]; None where none is seen. A car is in the ego's lane where it overlaps it
    sideways (its centre within ``WIDTH``)."""
    cars = np.asarray(observation, dtype=np.float64).reshape(CARS, FEATURES)
    nearest: tuple[float, float] | None = None
    for presence, x, y, vx, _ in cars[1:]:
        dx, dy = x * X_RANGE, y * Y_RANGE
        if presence > 0.5 and dx > 0.0 and abs(dy) < WIDTH:
            gap = dx - LENGTH
            if nearest is None or gap < nearest[0]:
                nearest = (gap, -vx * V_RANGE)
    return nearest


class GapKeeper:
    """#68's controller: accelerate towards ``TARGET_SPEED`` (``GAIN`` per m/s short, in the
    action's [-1, 1]) and brake fully only when the car ahead in the lane is within
    ``BRAKE_GAP`` or ``BRAKE_TTC`` of a collision. It keeps no distance otherwise, and decides
    once a second: it brakes late. Memoryless; the seed is unused."""

    def __init__(self, seed: int = 0) -> None:
        self.seed = seed

    def __call__(self, observation: np.ndarray) -> float:
        speed = float(np.asarray(observation).reshape(CARS, FEATURES)[0, 3]) * V_RANGE
        car = ahead(observation)
        if car is not None:
            gap, closing = car
            if gap < BRAKE_GAP or (closing > 0.0 and gap / closing < BRAKE_TTC):
                return -1.0
        return float(np.clip(GAIN * (TARGET_SPEED - speed), -1.0, 1.0))


def shield_observation(observation: np.ndarray) -> list[float]:
    """The Kinematics observation flattened: 25 numbers in [-1, 1]."""
    return [float(v) for v in np.asarray(observation).reshape(-1)]


def collision(observation: Any, info: dict[str, Any]) -> str | None:
    """``collision`` where highway-env says the ego crashed."""
    return "collision" if info["crashed"] else None


def collision_or_too_slow(observation: Any, info: dict[str, Any]) -> str | None:
    """``collision`` as :func:`collision`, else ``too_slow`` where :class:`SpeedTask` says the
    ego fell below ``TOO_SLOW``."""
    return collision(observation, info) or ("too_slow" if info["too_slow"] else None)


# What a new user writes (client.shield.config_for): highway-env's own spaces (the observation
# declared unbounded, the action [-1, 1] in 20 bins), the observation's range [-1, 1] given,
# and each failure with the direction of acceleration that moves away from it. The spaces are
# written out so that the configuration is built without highway-env installed;
# tests/test_highway_world.py checks them against the environment's.
SPACES = Spaces(
    observation_space=Box(-np.inf, np.inf, shape=(CARS, FEATURES), dtype=np.float32),
    action_space=Box(-1.0, 1.0, shape=(1,), dtype=np.float32),
)
LOW, HIGH = [-1.0] * (CARS * FEATURES), [1.0] * (CARS * FEATURES)
CONFIG: ShieldConfig = config_for(SPACES, {"collision": "decrease"}, low=LOW, high=HIGH)
CONFIG_TOO_SLOW: ShieldConfig = config_for(
    SPACES,
    {"collision": "decrease", "too_slow": "increase"},
    low=LOW,
    high=HIGH,
)

WORLD = World(
    name="highway",
    make=lambda seed: make_env(),
    controller=GapKeeper,
    config=CONFIG,
    event=collision,
    shield_observation=shield_observation,
    max_steps=MAX_STEPS,
)
WORLD_TOO_SLOW = World(
    name="highway-too-slow",
    make=lambda seed: make_env(TOO_SLOW),
    controller=GapKeeper,
    config=CONFIG_TOO_SLOW,
    event=collision_or_too_slow,
    shield_observation=shield_observation,
    max_steps=MAX_STEPS,
)


def alone(world: World, seed: int, episodes: int) -> dict[str, float]:
    """The controller alone on ``world`` over ``episodes`` episodes from ``seed``, with the
    harness's environment seeds: the share of episodes failed (by kind), the mean speed per
    step and the seconds per episode. The harness reports the task figure, not the speed."""
    env = world.make(seed)
    act = world.controller(seed)
    kinds: dict[str, float] = {}
    speeds: list[float] = []
    start = time.perf_counter()
    for episode in range(episodes):
        observation, info = env.reset(seed=seed * 100_003 + episode)
        for _ in range(world.max_steps):
            observation, _, terminated, truncated, info = env.step(np.array([act(observation)]))
            speeds.append(float(info["speed"]))
            event = world.event(observation, info)
            if event is not None:
                kinds[event] = kinds.get(event, 0.0) + 1.0 / episodes
            if event is not None or terminated or truncated:
                break
    return {
        **kinds,
        "failed": sum(kinds.values()),
        "speed": float(np.mean(speeds)),
        "seconds": (time.perf_counter() - start) / episodes,
    }


def main() -> None:
    """``python -m bench.worlds.highway``: the controller alone on both worlds, per seed, as a
    Markdown table."""
    parser = argparse.ArgumentParser(description=main.__doc__)
    parser.add_argument("--seeds", default="0,1,2")
    parser.add_argument("--episodes", type=int, default=60)
    args = parser.parse_args()
    print(
        f"Controller alone, {args.episodes} episodes a seed, "
        f"{platform.processor() or platform.machine()}.\n"
    )
    print("| world | seed | failed | by kind | mean speed [m/s] | s / episode |")
    print("|---|---|---|---|---|---|")
    for world in (WORLD, WORLD_TOO_SLOW):
        for seed in (int(s) for s in args.seeds.split(",")):
            row = alone(world, seed, args.episodes)
            kinds = ", ".join(
                f"{k} {v:.0%}" for k, v in row.items() if k not in ("failed", "speed", "seconds")
            )
            print(
                f"| {world.name} | {seed} | {row['failed']:.1%} | {kinds} | "
                f"{row['speed']:.1f} | {row['seconds']:.2f} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
