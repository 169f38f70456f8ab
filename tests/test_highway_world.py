"""highway-env's worlds (``bench/worlds/highway.py``): the adapter's figures, the failures, the
configuration a new user writes, and the worlds' registration without highway-env. Skipped
where highway-env (the optional extra ``highway``) is not installed, but for the last test,
which hides it."""

from __future__ import annotations

import subprocess
import sys
from types import ModuleType

import numpy as np
import pytest

from bench.worlds import highway as hw
from bench.worlds.harness import run


@pytest.fixture(scope="module")
def highway_env() -> ModuleType:
    """highway-env, or the test is skipped."""
    module: ModuleType = pytest.importorskip("highway_env")
    return module


def drive(
    env: hw.SpeedTask, seed: int, action: float, steps: int = hw.MAX_STEPS
) -> tuple[np.ndarray, bool, dict[str, object]]:
    """``action`` held from a reset with ``seed`` until the episode ends or ``steps`` pass:
    the last observation, whether it terminated, and the last info."""
    observation, info = env.reset(seed=seed)
    terminated = False
    for _ in range(steps):
        observation, _, terminated, truncated, info = env.step(np.array([action]))
        if terminated or truncated:
            break
    return observation, terminated, info


def test_the_declared_spaces_are_highway_envs_own(highway_env: ModuleType) -> None:
    env = hw.make_env()
    assert env.observation_space == hw.SPACES.observation_space
    assert env.action_space == hw.SPACES.action_space
    assert env.unwrapped.config["policy_frequency"] == 1  # type: ignore[attr-defined]
    observation, _ = env.reset(seed=0)
    assert len(hw.shield_observation(observation)) == 25
    assert all(-1.0 <= v <= 1.0 for v in hw.shield_observation(observation))


def test_the_configuration_names_each_failure_and_its_direction() -> None:
    for config in (hw.CONFIG, hw.CONFIG_TOO_SLOW):
        assert config.observation.low == (-1.0,) * 25 and config.observation.high == (1.0,) * 25
        assert (config.action.low, config.action.high) == (-1.0, 1.0)
    assert [(c.name, c.direction, c.bound) for c in hw.CONFIG.criteria] == [
        ("collision", "decrease", None)
    ]
    assert [(c.name, c.direction) for c in hw.CONFIG_TOO_SLOW.criteria] == [
        ("collision", "decrease"),
        ("too_slow", "increase"),
    ]
    assert hw.WORLD.config is hw.CONFIG and hw.WORLD_TOO_SLOW.config is hw.CONFIG_TOO_SLOW


def test_the_adapter_adds_the_speed_and_its_shortfall(highway_env: ModuleType) -> None:
    env = hw.make_env()
    _, info = env.reset(seed=3)
    assert info["speed"] == pytest.approx(25.0)  # highway-env starts the ego at 25 m/s
    assert info["task"] == pytest.approx(hw.TARGET_SPEED - 25.0)
    _, _, _, _, info = env.step(np.array([1.0]))  # 5 m/s² for 1 s
    speed = float(env.unwrapped.vehicle.speed)  # type: ignore[attr-defined]
    assert info["speed"] == speed == pytest.approx(30.0)
    assert info["task"] == pytest.approx(4.0)
    assert "too_slow" not in info and "crashed" in info


def test_a_crash_is_a_collision_and_ends_the_episode(highway_env: ModuleType) -> None:
    env = hw.make_env()
    for seed in range(10):  # flat out: the ego rear-ends the first slower car in its lane
        observation, terminated, info = drive(env, seed, 1.0)
        if info["crashed"]:
            break
    assert info["crashed"] and terminated
    assert hw.collision(observation, info) == "collision"
    assert hw.collision_or_too_slow(observation, {**info, "too_slow": False}) == "collision"
    observation, _ = env.reset(seed=0)
    assert hw.collision(observation, {"crashed": False}) is None


def test_too_slow_is_the_ego_below_20_m_s_and_ends_the_episode(highway_env: ModuleType) -> None:
    env = hw.make_env(hw.TOO_SLOW)
    observation, terminated, info = drive(env, 0, -1.0)  # full braking from 25 m/s
    assert terminated and info["too_slow"] and not info["crashed"]
    assert float(info["speed"]) < hw.TOO_SLOW  # type: ignore[arg-type]
    assert hw.collision_or_too_slow(observation, info) == "too_slow"
    _, _, info = drive(env, 0, 0.0, steps=1)  # at 25 m/s
    assert info["too_slow"] is False


def test_the_controller_reads_the_car_ahead_as_highway_env_places_it(
    highway_env: ModuleType,
) -> None:
    env = hw.make_env()
    checked = 0
    for seed in range(4):
        observation, _ = env.reset(seed=seed)
        road = env.unwrapped.road  # type: ignore[attr-defined]
        ego = env.unwrapped.vehicle  # type: ignore[attr-defined]
        front, _ = road.neighbour_vehicles(ego, ego.lane_index)
        car = hw.ahead(observation)
        if front is None or car is None:
            continue
        gap = float(front.position[0] - ego.position[0]) - hw.LENGTH
        assert car[0] == pytest.approx(gap, abs=0.05)
        assert car[1] == pytest.approx(float(ego.speed - front.speed), abs=0.05)
        checked += 1
    assert checked >= 2


def test_the_controller_tracks_34_m_s_and_brakes_only_when_close() -> None:
    def seen(speed: float, gap: float, closing: float) -> np.ndarray:
        cars = np.zeros((hw.CARS, hw.FEATURES))
        cars[0] = (1.0, 1.0, 0.0, speed / hw.V_RANGE, 0.0)
        cars[1] = (1.0, (gap + hw.LENGTH) / hw.X_RANGE, 0.0, -closing / hw.V_RANGE, 0.0)
        cars[2] = (1.0, 5.0 / hw.X_RANGE, hw.LANE_WIDTH / hw.Y_RANGE, -20.0 / hw.V_RANGE, 0.0)
        return cars

    act = hw.GapKeeper()
    # the car in the next lane, 5 m ahead and 14 m/s slower, is not the ego's
    assert act(seen(34.0, 60.0, 0.0)) == pytest.approx(0.0, abs=1e-6)
    assert act(seen(29.0, 60.0, 0.0)) == pytest.approx(1.0)  # 5 m/s short: full throttle
    assert act(seen(34.0, 11.0, -3.0)) == -1.0  # within 12 m
    assert act(seen(34.0, 30.0, 13.0)) == -1.0  # 2.3 s to collision
    assert act(seen(34.0, 30.0, 11.0)) == pytest.approx(0.0, abs=1e-6)  # 2.7 s


def test_both_worlds_run_alone_and_shielded(highway_env: ModuleType) -> None:
    for world in (hw.WORLD, hw.WORLD_TOO_SLOW):
        alone = run(world, seed=0, episodes=2, warmup=0, config=None)
        assert alone["task"] is not None and alone["steps"] > 0
        assert set(alone["failures"]) <= {c.name for c in world.config.criteria}
    shielded = run(hw.WORLD, seed=0, episodes=2, warmup=0, config=hw.CONFIG)
    assert shielded["states"] > 0 and shielded["task"] is not None


def test_the_worlds_are_registered_and_ask_for_highway_env_only_when_run() -> None:
    code = """
import sys
sys.modules["highway_env"] = None  # as if not installed
from bench.worlds.__main__ import world_named
from bench.worlds.tuning import WORLDS
assert WORLDS["highway"].name == "highway" and "highway_too_slow" in WORLDS
assert world_named("tuning_tank").name
try:
    world_named("highway")
except SystemExit as error:
    print(error)
try:
    WORLDS["highway_too_slow"].make(0)
except ModuleNotFoundError as error:
    print(error)
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=False)
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    assert len(lines) == 2 and all("efsm-shield[highway]" in line for line in lines)
