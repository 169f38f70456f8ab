"""Stable-Baselines3 learns from what the shield applied, not from what it proposed.

SB3's off-policy algorithms (TD3, DDPG, SAC) store the action the policy proposed. Behind a
:class:`~client.shield.wrapper.ShieldWrapper` the environment did something else whenever the
shield revised, and a critic trained on the proposal learns a transition that never happened.
This buffer stores ``info["applied_action"]`` instead::

    model = TD3("MlpPolicy", ShieldWrapper(env), replay_buffer_class=AppliedActionReplayBuffer)

:class:`Failures` is a callback that counts what the shield saw during training, and can
report it as it goes.

Needs ``stable-baselines3`` (``pip install .[sb3]``).
"""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Callable
from typing import Any

import numpy as np
from gymnasium import spaces
from stable_baselines3.common.buffers import ReplayBuffer
from stable_baselines3.common.callbacks import BaseCallback


class AppliedActionReplayBuffer(ReplayBuffer):
    """A :class:`ReplayBuffer` that records the action each environment copy applied."""

    def add(
        self,
        obs: np.ndarray,
        next_obs: np.ndarray,
        action: np.ndarray,
        reward: np.ndarray,
        done: np.ndarray,
        infos: list[dict[str, Any]],
    ) -> None:
        assert isinstance(self.action_space, spaces.Box)
        low, high = self.action_space.low, self.action_space.high
        action = np.array(action, copy=True).reshape((self.n_envs, self.action_dim))
        for i, info in enumerate(infos):
            applied = info.get("applied_action")
            if applied is not None:  # stored as SB3 stores actions: scaled to [-1, 1]
                scaled = 2.0 * (np.asarray(applied).reshape(-1) - low) / (high - low) - 1.0
                action[i] = scaled.reshape(-1)
        super().add(obs, next_obs, action, reward, done, infos)


class Failures(BaseCallback):
    """Counts, over a training, the failures the environment reports in ``info[key]``, the
    episodes and the steps the shield revised.

    With ``report`` (``print``, a logger's ``info``), it hands it :meth:`progress` every
    ``every_s`` seconds of training, so that a long training says how it goes.
    """

    def __init__(
        self,
        key: str = "event",
        report: Callable[[str], object] | None = None,
        every_s: float = 30.0,
    ) -> None:
        super().__init__()
        self.key = key
        self.failures: Counter[str] = Counter()
        self.episodes = 0
        self.revised = 0
        self.report = report
        self.every_s = every_s
        self._start = self._next = 0.0

    def _on_training_start(self) -> None:
        self._start = time.monotonic()
        self._next = self._start + self.every_s

    def _on_step(self) -> bool:
        for info, done in zip(self.locals["infos"], self.locals["dones"], strict=True):
            if info.get(self.key):
                self.failures[info[self.key]] += 1
            self.episodes += bool(done)
            shield = info.get("shield")
            self.revised += bool(shield and shield["revised"])
        if self.report is not None and time.monotonic() >= self._next:
            self._next = time.monotonic() + self.every_s
            self.report(self.progress())
        return True

    def progress(self) -> str:
        """One line: steps done of the training's, episodes, failures, revisions, seconds."""
        total = self.model._total_timesteps
        return (
            f"{self.num_timesteps}/{total} steps, {self.episodes} episodes, "
            f"{sum(self.failures.values())} failures {dict(self.failures)}, "
            f"{self.revised} revised, {time.monotonic() - self._start:.0f} s"
        )
