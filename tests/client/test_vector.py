"""ShieldVectorWrapper: one shield model for every copy of a vectorised environment."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AsyncVectorEnv, AutoresetMode, SyncVectorEnv

from client.shield import LocalShield, ShieldVectorWrapper, ShieldWrapper, SpaceMismatch
from tests.client.test_wrapper import EDGE, Ledge, ledge_config
from tests.utils import assert_same


def ledges(n: int, **kwargs: Any) -> SyncVectorEnv:
    return SyncVectorEnv([lambda: Ledge(**kwargs) for _ in range(n)])


def pushes(rng: np.random.Generator, n: int) -> np.ndarray:
    return rng.uniform(-0.5, 1.0, size=(n, 1)).astype(np.float32)


def test_one_copy_decides_and_learns_as_the_single_wrapper_does() -> None:
    """The vector wrapper over one copy against ShieldWrapper over the same environment, the
    same seed and proposals: the same applied actions and the same model. The step after an
    episode's end only resets the copy, so the single environment is reset there instead."""
    vector = ShieldVectorWrapper(ledges(1), config=ledge_config(), stream_prefix="car")
    single = ShieldWrapper(Ledge(), config=ledge_config(), stream="car-0")
    vector.reset(seed=3)
    single.reset(seed=3)
    rng = np.random.default_rng(1)
    resetting, episodes = False, 0
    for _ in range(600):
        action = pushes(rng, 1)
        _, _, terminated, truncated, info = vector.step(action)
        if resetting:  # the copy reset itself and ignored the action
            assert not info["_shield"][0]
            single.reset()
            resetting = False
            continue
        _, _, done, cut, one = single.step(action[0])
        assert info["shield"][0] == one["shield"]
        assert info["applied_action"][0] == pytest.approx(one["applied_action"])
        assert (terminated[0], truncated[0]) == (done, cut)
        resetting = bool(terminated[0] or truncated[0])
        episodes += resetting
    assert isinstance(vector.shield, LocalShield) and isinstance(single.shield, LocalShield)
    assert episodes > 20 and vector.shield.shield.counters.interventions["edge"] > 0
    assert_same(vector.shield.shield.snapshot(), single.shield.shield.snapshot())


def test_every_copy_is_a_stream_of_one_model_closed_at_its_episode_end() -> None:
    shield = LocalShield(ledge_config())
    envs = ShieldVectorWrapper(ledges(3), shield=shield, stream_prefix="ledge")
    assert envs.streams == ["ledge-0", "ledge-1", "ledge-2"]
    envs.reset(seed=0)
    rng = np.random.default_rng(0)
    ended = 0
    for _ in range(200):
        _, _, terminated, truncated, info = envs.step(pushes(rng, 3))
        over = terminated | truncated
        assert (info["_shield_done"] == over).all()
        for i in np.flatnonzero(over):
            assert f"ledge-{i}" not in shield.shield.streams  # closed, not learned across
            assert info["shield_done"][i]["reason"] == "done"
        ended += int(over.sum())
    assert shield.shield.counters.episodes == ended > 10
    envs.close()
    assert not shield.shield.streams  # close() ended the open episodes
    assert shield.shield.n_states > 0  # the shield passed in stays the caller's


def test_evaluation_learns_nothing_and_the_seed_seeds_the_shield() -> None:
    runs = []
    for _ in range(2):
        envs = ShieldVectorWrapper(ledges(2), config=ledge_config())
        assert isinstance(envs.shield, LocalShield)
        envs.reset(seed=11)
        rng = np.random.default_rng(2)
        runs.append([envs.step(pushes(rng, 2))[4]["applied_action"].tolist() for _ in range(300)])
        envs.set_evaluation(True)
        before = envs.shield.shield.snapshot()
        for _ in range(50):
            envs.step(pushes(rng, 2))
        assert envs.shield.shield.counters.model_version == before["counters"]["model_version"]
        assert envs.shield.shield.config.reviser.seed == 11
    assert runs[0] == runs[1]


def test_copies_in_worker_processes_share_the_model_in_this_one() -> None:
    envs = ShieldVectorWrapper(
        AsyncVectorEnv([lambda: Ledge() for _ in range(2)]),
        config=ledge_config(),
        failure=lambda o, r, t, c, i: i["event"],
    )
    envs.reset(seed=4)
    rng = np.random.default_rng(4)
    for _ in range(100):
        envs.step(pushes(rng, 2))
    assert isinstance(envs.shield, LocalShield)
    shield = envs.shield.shield
    assert shield.counters.steps >= 200 and shield.counters.episodes > 2
    envs.close()


def test_what_the_vector_wrapper_cannot_follow_is_refused_at_construction() -> None:
    with pytest.raises(SpaceMismatch) as error:
        ShieldVectorWrapper(ledges(2, dims=2), criteria=EDGE)
    assert error.value.field == "action_space"
    same_step = SyncVectorEnv([lambda: Ledge()], autoreset_mode=AutoresetMode.SAME_STEP)
    with pytest.raises(SpaceMismatch) as error:
        ShieldVectorWrapper(same_step, config=ledge_config())
    assert error.value.field == "autoreset_mode"
    with pytest.raises(SpaceMismatch, match="name the failures"):
        ShieldVectorWrapper(gym.make_vec("Pendulum-v1", num_envs=2))
    with pytest.raises(gym.error.ResetNeeded):
        ShieldVectorWrapper(ledges(1), config=ledge_config()).step(np.zeros((1, 1)))
