"""The shield as a Gymnasium and Stable-Baselines3 user meets it: ShieldWrapper, config_for,
the replay buffer that learns the applied action, the registered environment."""

from __future__ import annotations

import json
import subprocess
import sys
import warnings
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

from app.core import Bound, InvalidConfig, ReviserConfig, ShieldConfig
from client.shield import (
    LocalShield,
    NoFailureReported,
    ShieldVectorWrapper,
    ShieldWrapper,
    SpaceMismatch,
    config_for,
    sample_observations,
)
from client.shield.spaces import SAMPLE_MARGIN
from client.shield.wrapper import SILENT_EPISODES
from client.sim.car_following import CarFollowingEnv
from client.sim.lead import synthetic
from tests.core.checks import risk_parts

EDGE = {"edge": "decrease"}  # pushing less is safer


def ledge_config(criteria: dict[str, str] = EDGE) -> ShieldConfig:
    """The shield for :class:`Ledge`, revising from its sixth episode."""
    return config_for(
        Ledge(), criteria, base=ShieldConfig(reviser=ReviserConfig(activate_after_episodes=5))
    )


class Ledge(gym.Env[np.ndarray, np.ndarray]):
    """A point pushed along [0, 1] by its action; beyond 0.9 it falls off ("edge", the episode
    ends); ``bumps`` also reports a "bump" above 0.7 without ending the episode. ``key`` is
    where ``info`` tells the failure (highway-env says ``"crashed"``); ``bounded=False``
    declares the observation space ``Box(-inf, inf)``, as highway-env does."""

    def __init__(
        self, bumps: bool = False, dims: int = 1, key: str = "event", bounded: bool = True
    ) -> None:
        low, high = (0.0, 1.0) if bounded else (-np.inf, np.inf)
        self.observation_space = gym.spaces.Box(low, high, shape=(1,), dtype=np.float64)
        self.action_space = gym.spaces.Box(-1.0, 1.0, shape=(dims,), dtype=np.float32)
        self.bumps = bumps
        self.key = key
        self.x, self.t = 0.5, 0

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        self.x, self.t = float(self.np_random.uniform(0.3, 0.6)), 0
        return np.array([self.x]), {}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        assert action.shape == self.action_space.shape and action.dtype == np.float32
        self.x = float(np.clip(self.x + 0.1 * float(action[0]), 0.0, 1.0))
        self.t += 1
        fell = self.x > 0.9
        event = "edge" if fell else ("bump" if self.bumps and self.x > 0.7 else None)
        return np.array([self.x]), float(self.x), fell, self.t >= 30, {self.key: event}


def pushing(episodes: int, env: gym.Env[Any, Any], seed: int = 0) -> list[dict[str, Any]]:
    """A controller that mostly pushes forwards; every step's info."""
    rng = np.random.default_rng(seed)
    infos = []
    for episode in range(episodes):
        env.reset(seed=seed * 1000 + episode)
        while True:
            _, _, terminated, truncated, info = env.step(
                np.array([rng.uniform(-0.5, 1.0)], np.float32)
            )
            infos.append(info)
            if terminated or truncated:
                break
    return infos


def test_the_shield_wrapper_learns_a_ledge_and_keeps_the_point_on_it() -> None:
    alone = sum(i["event"] == "edge" for i in pushing(60, Ledge()))
    env = ShieldWrapper(Ledge(), config=ledge_config())
    infos = pushing(60, env)
    assert sum(i["event"] == "edge" for i in infos) < alone / 2
    revised = [i for i in infos if i["shield"]["revised"]]
    assert revised and all(i["applied_action"][0] < i["proposed_action"] for i in revised)
    json.dumps(infos[-1]["shield"]), json.dumps(infos[-1]["shield_done"])  # JSON-able
    assert all(float(i["applied_action"][0]) == pytest.approx(i["shield"]["action"]) for i in infos)


def test_several_action_dimensions_are_refused_at_construction() -> None:
    with pytest.raises(SpaceMismatch, match="one action dimension") as error:
        ShieldWrapper(Ledge(dims=2), criteria=EDGE)
    assert error.value.field == "action_space"


def test_config_for_reads_the_spaces_and_asks_for_what_they_cannot_say() -> None:
    pendulum = gym.make("Pendulum-v1")
    with pytest.raises(SpaceMismatch, match="name the failures") as error:
        config_for(pendulum)
    assert error.value.field == "criteria"
    config = config_for(pendulum, {"overspeed_cw": "increase", "overspeed_ccw": "decrease"})
    assert config.observation.low == (-1.0, -1.0, -8.0)
    assert (config.action.low, config.action.high, config.action.n_bins) == (-2.0, 2.0, 20)
    assert [c.name for c in config.criteria] == ["overspeed_cw", "overspeed_ccw"]
    bounded = config_for(
        pendulum,
        {"overspeed_cw": ("increase", Bound("x2", below=-6.0)), "overspeed_ccw": "decrease"},
    )
    assert [c.bound for c in bounded.criteria] == [Bound("x2", below=-6.0), None]
    # a failure whose saving direction depends on the state: none declared, with or without
    # a bound
    either = config_for(pendulum, {"overspeed": None, "still": (None, Bound("x2", below=-7.0))})
    assert [c.direction for c in either.criteria] == [None, None]
    assert either.criteria[1].bound == Bound("x2", below=-7.0)
    with pytest.raises(InvalidConfig) as refused:
        config_for(pendulum, {"overspeed_cw": ("increase", Bound("theta_dot", below=-6.0))})
    assert refused.value.field == "criteria.0.bound.observation"
    unbounded = gym.make("MountainCarContinuous-v0")
    unbounded.observation_space = gym.spaces.Box(-np.inf, np.inf, shape=(2,))
    with pytest.raises(SpaceMismatch, match="leaves all 2 of its numbers unbounded"):
        config_for(unbounded, EDGE)
    assert config_for(unbounded, EDGE, low=[-1.2, -0.07], high=[0.6, 0.07]).observation.high == (
        0.6,
        0.07,
    )
    assert config_for(CarFollowingEnv(lead=synthetic(0, count=2))) == ShieldConfig()


def test_a_configuration_that_does_not_fit_the_environment_fails_at_construction() -> None:
    with pytest.raises(SpaceMismatch, match="below the environment's -1.0") as error:
        ShieldWrapper(gym.make("MountainCarContinuous-v0"), config=ShieldConfig())
    assert error.value.field == "action.low"
    with pytest.raises(SpaceMismatch, match="observes 3 numbers") as error:
        ShieldWrapper(Ledge(), config=ShieldConfig(action=config_for(Ledge(), EDGE).action))
    assert error.value.field == "observation.names"


def test_every_copy_has_a_stream_and_a_reset_mid_episode_closes_it() -> None:
    shared = LocalShield(config_for(Ledge(), EDGE))
    envs = [ShieldWrapper(Ledge(), shared) for _ in range(3)]
    assert len({e.stream for e in envs}) == 3
    for i, env in enumerate(envs):
        env.reset(seed=i)
        env.step(np.array([0.1], np.float32))
    assert set(shared.shield.streams) == {e.stream for e in envs}
    episodes = shared.shield.counters.episodes
    envs[0].reset()  # mid-episode
    assert envs[0].stream not in shared.shield.streams
    assert shared.shield.counters.episodes == episodes + 1


def test_vectorised_copies_write_streams_of_their_own() -> None:
    from stable_baselines3.common.env_util import make_vec_env

    shared = LocalShield(config_for(Ledge(), EDGE))
    venv = make_vec_env(
        Ledge, n_envs=4, seed=0, wrapper_class=ShieldWrapper, wrapper_kwargs={"shield": shared}
    )
    venv.reset()
    for _ in range(3):
        venv.step(np.zeros((4, 1), np.float32))
    assert len(shared.shield.streams) == 4
    assert shared.shield.counters.steps == 3 * 4  # a reset alone sends the shield nothing
    venv.close()


def test_gymnasium_vector_envs_take_the_wrapper_per_copy() -> None:
    import functools

    shared = LocalShield(config_for(Ledge(), EDGE))
    # gymnasium types entry_point as a callable of **kwargs: Any; it takes a class as well
    gym.register("LedgeForTest-v0", entry_point=Ledge)  # type: ignore[arg-type]
    venv = gym.make_vec(
        "LedgeForTest-v0",
        num_envs=3,
        vectorization_mode="sync",
        wrappers=[functools.partial(ShieldWrapper, shield=shared)],
    )
    venv.reset(seed=0)
    for _ in range(4):
        _, _, _, _, info = venv.step(np.zeros((3, 1), np.float32))
    assert len(shared.shield.streams) == 3 and shared.shield.counters.steps == 12
    assert list(info["shield"]["stream"]) == list(shared.shield.streams)  # info per copy
    venv.close()


def test_a_failure_that_does_not_end_the_episode_is_learned() -> None:
    env = ShieldWrapper(
        Ledge(bumps=True), config=ledge_config({"edge": "decrease", "bump": "decrease"})
    )
    infos = pushing(5, env)
    bumps = sum(i["event"] == "bump" for i in infos)
    assert bumps > 0
    learned = risk_parts(env.shield.shield).local_risk.failures  # type: ignore[attr-defined]
    assert learned[1] == bumps


def test_a_failure_predicate_replaces_info() -> None:
    def low(
        observation: Any, reward: float, terminated: bool, truncated: bool, info: dict[str, Any]
    ) -> str | None:
        return "edge" if observation[0] > 0.8 else None  # before the ledge itself

    env = ShieldWrapper(Ledge(), criteria=EDGE, failure=low)
    pushing(5, env)
    assert risk_parts(env.shield.shield).local_risk.failures.sum() > 0  # type: ignore[attr-defined]


def test_the_same_seed_gives_the_same_shield_and_evaluation_learns_nothing() -> None:
    def decisions(seed: int) -> list[dict[str, Any]]:
        """The paper's reviser, whose revisions carry noise from the shield's seed."""
        config = config_for(
            Ledge(),
            EDGE,
            base=ShieldConfig.paper(
                reviser=ReviserConfig(method="paper", activate_after_episodes=5)
            ),
        )
        env = ShieldWrapper(Ledge(), config=config, stream="point")
        env.reset(seed=seed)
        return [i["shield"] for i in pushing(40, env, seed=1)]

    assert decisions(3) == decisions(3)
    assert decisions(3) != decisions(4)
    env = ShieldWrapper(Ledge(), config=ledge_config())
    pushing(20, env)
    env.set_evaluation(True)
    version = env.shield.shield.counters.model_version  # type: ignore[attr-defined]
    infos = pushing(5, env)
    assert env.shield.shield.counters.model_version == version  # type: ignore[attr-defined]
    assert all(i["shield"]["model_version"] == version for i in infos)


def test_warm_up_in_steps_reports_but_does_not_revise() -> None:
    env = ShieldWrapper(Ledge(), config=ledge_config(), warmup_steps=10**6)
    infos = pushing(40, env)
    would = [i for i in infos if i["shield"]["revised"]]
    assert would and all(i["shield"]["shadow"] for i in would)
    assert all(
        i["applied_action"][0] == pytest.approx(i["proposed_action"], abs=1e-6) for i in infos
    )


def test_the_wrapper_closes_only_the_shield_it_made() -> None:
    closed: list[str] = []

    class Recorder(LocalShield):
        def close(self) -> None:
            closed.append("closed")

    ShieldWrapper(Ledge(), Recorder(config_for(Ledge(), EDGE))).close()
    assert not closed


def test_the_environment_is_registered_with_its_time_limit() -> None:
    code = (
        "import gymnasium as gym; env = gym.make('client.sim:CarFollowing-v0'); "
        "print(env.spec.max_episode_steps)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "800"


def test_sb3_learns_from_the_applied_action() -> None:
    from stable_baselines3 import TD3
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.noise import NormalActionNoise

    from client.shield.sb3 import AppliedActionReplayBuffer, Failures

    class Applied(BaseCallback):
        def __init__(self) -> None:
            super().__init__()
            self.applied: list[float] = []
            self.revised = 0

        def _on_step(self) -> bool:
            info = self.locals["infos"][0]
            self.applied.append(float(info["applied_action"][0]))
            self.revised += info["shield"]["revised"]
            return True

    env = ShieldWrapper(Ledge(), config=ledge_config())
    pushing(40, env)  # the shield has met the ledge before the learner starts
    pushy = NormalActionNoise(mean=np.array([0.6]), sigma=np.array([0.3]))  # towards the ledge
    model = TD3(
        "MlpPolicy",
        env,
        learning_starts=50,
        train_freq=1,
        seed=0,
        action_noise=pushy,
        replay_buffer_class=AppliedActionReplayBuffer,
        policy_kwargs={"net_arch": [16, 16]},
    )
    callback = Applied()
    lines: list[str] = []
    failures = Failures(report=lines.append, every_s=0.0)  # a progress line every step
    model.learn(total_timesteps=300, callback=[callback, failures])
    assert callback.revised > 0
    assert len(lines) == 300 and lines[-1].startswith("300/300 steps, ")
    assert f"{failures.revised} revised" in lines[-1] and failures.revised == callback.revised
    assert f"{sum(failures.failures.values())} failures" in lines[-1]
    stored = model.replay_buffer.actions[:300, 0, 0]  # type: ignore[union-attr]
    np.testing.assert_allclose(stored, np.array(callback.applied), atol=1e-6)  # [-1, 1] here


def crashed(
    observation: Any, reward: float, terminated: bool, truncated: bool, info: dict[str, Any]
) -> str | None:
    """Ledge's failure where it reports it as highway-env does, under ``info["crashed"]``."""
    return "edge" if info["crashed"] else None


def silence_warnings(env: gym.Env[Any, Any], episodes: int) -> list[warnings.WarningMessage]:
    """The :class:`NoFailureReported` warnings of ``episodes`` episodes pushed into ``env``,
    each shown (no filter hides a repeat)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        pushing(episodes, env)
    return [w for w in caught if issubclass(w.category, NoFailureReported)]


def test_failures_reported_under_another_key_warn_once_and_say_how_to_pass_them() -> None:
    env = ShieldWrapper(Ledge(key="crashed"), config=ledge_config())
    caught = silence_warnings(env, 60)
    assert len(caught) == 1  # once, however many silent episodes follow
    message = str(caught[0].message)
    assert f"{SILENT_EPISODES} episodes terminated" in message
    assert "info['event'], which this environment never sets" in message
    assert "failure(observation, reward, terminated, truncated, info)" in message
    assert "criteria: edge" in message
    assert caught[0].filename == __file__  # it points at the caller's step()
    assert risk_parts(env.shield.shield).local_risk.failures.sum() == 0  # type: ignore[attr-defined]
    # the advice works: the same environment with failure= learns and does not warn
    told = ShieldWrapper(Ledge(key="crashed"), config=ledge_config(), failure=crashed)
    assert silence_warnings(told, 60) == []
    assert risk_parts(told.shield.shield).local_risk.failures.sum() > 0  # type: ignore[attr-defined]


def test_no_warning_while_failures_come_or_episodes_end_otherwise() -> None:
    assert silence_warnings(ShieldWrapper(Ledge(), config=ledge_config()), 60) == []
    timid = ShieldWrapper(Ledge(key="crashed"), config=ledge_config())
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for episode in range(10):  # never reaches the ledge: every episode is truncated
            timid.reset(seed=episode)
            while not any(timid.step(np.array([-1.0], np.float32))[2:4]):
                pass
    assert not [w for w in caught if issubclass(w.category, NoFailureReported)]
    assert timid.watch.terminated == 0
    counting = ShieldWrapper(Ledge(key="crashed"), config=ledge_config())
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        counting.reset(seed=0)
        while counting.watch.terminated < SILENT_EPISODES - 1:
            if any(counting.step(np.array([1.0], np.float32))[2:4]):
                counting.reset()
    assert not [w for w in caught if issubclass(w.category, NoFailureReported)]  # one short


def test_a_predicate_that_never_fires_warns_about_itself() -> None:
    def never(
        observation: Any, reward: float, terminated: bool, truncated: bool, info: dict[str, Any]
    ) -> str | None:
        return None

    caught = silence_warnings(ShieldWrapper(Ledge(), config=ledge_config(), failure=never), 20)
    assert len(caught) == 1 and "failure= predicate returned None at every step" in str(
        caught[0].message
    )


def test_a_predicate_of_the_wrong_shape_is_refused_with_the_five_arguments() -> None:
    with pytest.raises(
        TypeError,
        match=r"failure\(observation, reward, terminated, "
        r"truncated, info\)",
    ):
        # the wrong shape, deliberately: the refusal is under test
        ShieldWrapper(Ledge(), criteria=EDGE, failure=lambda info: info.get("crashed"))  # type: ignore[arg-type,misc]
    yes_no = ShieldWrapper(Ledge(), criteria=EDGE, failure=lambda o, r, te, tr, info: te)  # type: ignore[arg-type,return-value]
    yes_no.reset(seed=0)
    with pytest.raises(TypeError, match="the name of the criterion that failed .* not False"):
        yes_no.step(np.array([0.0], np.float32))


def test_the_vector_wrapper_warns_as_the_wrapper_does() -> None:
    gym.register(
        "LedgeCrashedForTest-v0",
        entry_point=Ledge,  # type: ignore[arg-type]  # a class, as above
        kwargs={"key": "crashed"},
    )
    envs = ShieldVectorWrapper(
        gym.make_vec("LedgeCrashedForTest-v0", num_envs=2, vectorization_mode="sync"),
        config=ledge_config(),
    )
    envs.reset(seed=0)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for _ in range(200):  # full push: each copy falls off every few steps
            envs.step(np.ones((2, 1), np.float32))
    assert envs.watch.terminated > SILENT_EPISODES
    assert len([w for w in caught if issubclass(w.category, NoFailureReported)]) == 1
    envs.close()


def test_an_unbounded_observation_space_is_refused_and_names_both_ways_out() -> None:
    with pytest.raises(SpaceMismatch) as error:
        ShieldWrapper(Ledge(bounded=False), criteria=EDGE)
    assert error.value.field == "observation_space"
    assert "Box(-inf, inf, (1,), float64)" in str(error.value)
    assert "low=[...], high=[...]" in str(error.value)
    assert "observations=sample_observations(env)" in str(error.value)
    given = config_for(Ledge(bounded=False), EDGE, low=[0.0], high=[1.0])
    assert (given.observation.low, given.observation.high) == ((0.0,), (1.0,))
    with pytest.raises(SpaceMismatch, match=r"one bound per observation number \(1\)") as size:
        config_for(Ledge(bounded=False), EDGE, low=[0.0, 0.0], high=[1.0])
    assert size.value.field == "low"


def test_a_sample_of_observations_gives_the_range_widened_by_the_margin() -> None:
    sample = np.array([[0.2, 5.0], [0.6, 5.0], [0.4, 5.0]])
    env = gym.make("MountainCarContinuous-v0")
    env.observation_space = gym.spaces.Box(-np.inf, np.inf, shape=(2,))
    config = config_for(env, EDGE, observations=sample)
    assert config.observation.low == pytest.approx((0.2 - SAMPLE_MARGIN * 0.4, 5.0 - 5.0 * 0.1))
    assert config.observation.high == pytest.approx((0.6 + SAMPLE_MARGIN * 0.4, 5.0 + 5.0 * 0.1))
    # a number that varies by a rounding error only counts as one that never varied
    nearly = config_for(env, EDGE, observations=sample + [[0.0, 0.0], [0.0, 1e-9], [0.0, 0.0]])
    assert nearly.observation.high[1] == pytest.approx(5.0 + 5.0 * 0.1)
    # low=/high= win over the sample, per bound
    mixed = config_for(env, EDGE, observations=sample, high=[1.0, 9.0])
    assert mixed.observation.high == (1.0, 9.0)
    assert mixed.observation.low == config.observation.low
    for bad, message in (
        (np.zeros((3, 3)), r"rows of the observation's 2 numbers"),
        ([[0.0, np.nan]], "not finite"),
        ([], "shape \\(0,\\)"),
        ([["a", "b"]], "an array of numbers"),
    ):
        with pytest.raises(SpaceMismatch, match=message) as error:
            config_for(env, EDGE, observations=bad)
        assert error.value.field == "observations"


def test_sample_observations_reads_what_the_shield_sees() -> None:
    sample = sample_observations(Ledge(bounded=False), steps=120, seed=3)
    assert sample.shape == (120, 1) and ((0.0 <= sample) & (sample <= 1.0)).all()
    np.testing.assert_array_equal(sample, sample_observations(Ledge(bounded=False), 120, 3))
    assert not np.array_equal(sample, sample_observations(Ledge(bounded=False), 120, 4))
    cars = sample_observations(CarFollowingEnv(lead=synthetic(0, count=2)), steps=50)
    assert cars.shape == (50, 3)  # info["efsm_observation"], not the observation
    env = ShieldWrapper(
        Ledge(bounded=False), config=config_for(Ledge(bounded=False), EDGE, observations=sample)
    )
    pushing(3, env)  # the derived configuration guards the environment
