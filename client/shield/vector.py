"""The shield in front of a vectorised Gymnasium environment: one model for every copy.

    envs = ShieldVectorWrapper(gym.make_vec("client.sim:CarFollowing-v0", num_envs=8))

Every copy is a stream of its own (``{prefix}-{i}``) of one shield model, so that what one copy
learns protects the others, whether the copies step in this process (``SyncVectorEnv``) or in
worker processes (``AsyncVectorEnv``): the wrapper and its shield stay in this process.
:class:`~client.shield.wrapper.ShieldWrapper` around each copy instead gives each copy a model
of its own (or a shared service through ``shield=``).

The copies reset themselves in Gymnasium's default way (``autoreset_mode`` ``NextStep``): the
step after a copy's episode ends only resets it and ignores its action, so that step is not
sent to the shield. ``info`` gains, per copy (with Gymnasium's ``_key`` masks): ``shield``
(the decision record), ``shield_done`` where an episode ended, and the arrays
``applied_action`` and ``proposed_action``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode

from app.core import ShieldConfig
from client.shield.base import StepShield
from client.shield.spaces import SpaceMismatch, check_observation, one_dimensional
from client.shield.wrapper import (
    Failure,
    FailureWatch,
    bind,
    check_failure,
    default_stream,
    reported,
    reseeded,
)


class ShieldVectorWrapper(gym.vector.VectorWrapper):
    """Revise every copy's proposed action with one shield, a stream per copy.

    The options are :class:`~client.shield.wrapper.ShieldWrapper`'s: ``shield`` (else a
    :class:`LocalShield` of ``config``, default :func:`config_for` the copies with
    ``criteria``, seeded by the first ``reset(seed=...)``), ``failure`` (called per copy
    with that copy's observation, reward, flags and info) or ``info[event_key]``,
    ``observation_key``, ``warmup_steps`` (vector steps in which the shield only reports) and
    ``shadow``; it warns as :class:`ShieldWrapper` does when the copies' episodes terminate
    and no failure is ever reported (:class:`~client.shield.wrapper.FailureWatch`, over all
    copies).
    """

    def __init__(
        self,
        env: gym.vector.VectorEnv[Any, Any, Any],
        shield: StepShield | None = None,
        *,
        config: ShieldConfig | None = None,
        criteria: Mapping[str, str] | None = None,
        failure: Failure | None = None,
        event_key: str = "event",
        observation_key: str = "efsm_observation",
        stream_prefix: str | None = None,
        warmup_steps: int = 0,
        shadow: bool = False,
    ) -> None:
        super().__init__(env)
        one_dimensional(env.single_action_space)
        check_failure(failure)
        mode = env.metadata.get("autoreset_mode", AutoresetMode.NEXT_STEP)
        if AutoresetMode(mode) != AutoresetMode.NEXT_STEP:
            raise SpaceMismatch(
                f"the shield follows copies that reset themselves on the next "
                f"step (AutoresetMode.NEXT_STEP, Gymnasium's default), not "
                f"{AutoresetMode(mode)}",
                "autoreset_mode",
            )
        self._owned = shield is None
        self.config, self.shield = bind(
            env, shield, config, criteria, observation_key, warmup_steps
        )
        self.failure = failure
        self.event_key = event_key
        self.watch = FailureWatch(failure, event_key, self.config)
        self.observation_key = observation_key
        prefix = stream_prefix if stream_prefix is not None else default_stream()
        self.streams = [f"{prefix}-{i}" for i in range(env.num_envs)]
        self.warmup_steps = warmup_steps
        self.shadow = shadow
        self.evaluation = False
        self.steps = 0  # vector steps, for the warm-up
        self._seeded = False
        n = env.num_envs
        self._z: list[list[float] | None] = [None] * n  # None: the copy resets at its next step
        self._open = [False] * n
        self._event: list[str | None] = [None] * n
        self._started = False

    def set_evaluation(self, on: bool = True) -> None:
        """Evaluation mode: the shield still revises but learns nothing."""
        self.evaluation = on

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        for i in range(self.num_envs):
            if self._open[i]:  # an episode left mid-way: its stream ends, no failure learned
                self._end(i, self._z[i], None)
        if seed is not None and self._owned and not self._seeded and self.steps == 0:
            self._seeded = True
            self.shield.close()
            self.config, self.shield = reseeded(self.config, seed)
        observations, infos = self.env.reset(seed=seed, options=options)
        self._z = [self._observe(observations, infos, i) for i in range(self.num_envs)]
        if self.config is not None:
            check_observation(self.config, len(self._z[0] or []), self.observation_key)
        self._event = [None] * self.num_envs
        self._started = True
        return observations, infos

    def step(self, actions: Any) -> tuple[Any, Any, Any, Any, dict[str, Any]]:
        if not self._started:
            raise gym.error.ResetNeeded("call reset() before step()")
        n = self.num_envs
        proposed = np.asarray(actions, dtype=np.float64).reshape(n, -1)[:, 0]
        applied = proposed.copy()
        records: list[dict[str, Any] | None] = [None] * n
        shadow = self.shadow or self.steps < self.warmup_steps
        for i in range(n):
            z = self._z[i]
            if z is None:  # this step only resets copy i: its action is ignored
                continue
            decision = self.shield.revise(
                z,
                float(proposed[i]),
                stream=self.streams[i],
                event=self._event[i],
                shadow=shadow,
                learn=not self.evaluation,
            )
            assert decision.action is not None
            applied[i], records[i] = decision.action, decision.to_dict()
            self._open[i], self._event[i] = True, None
        self.steps += 1
        space = self.env.action_space
        given = applied.astype(space.dtype).reshape(space.shape)
        observations, rewards, terminated, truncated, infos = self.env.step(given)
        done: list[dict[str, Any] | None] = [None] * n
        for i in range(n):
            if records[i] is None:  # copy i was reset: its new episode starts here
                self._z[i] = self._observe(observations, infos, i)
                continue
            info = _one(infos, i)
            event = reported(
                self.failure,
                self.event_key,
                observations[i],
                float(rewards[i]),
                bool(terminated[i]),
                bool(truncated[i]),
                info,
            )
            self.watch.step(event, bool(terminated[i]), info)
            z = self._observe(observations, infos, i)
            if terminated[i] or truncated[i]:
                done[i] = self._end(i, z, event)
                self._z[i] = None
            else:
                self._z[i], self._event[i] = z, event
        infos = {
            **infos,
            **_masked("shield", records),
            **_masked("shield_done", done),
            "applied_action": given,
            "proposed_action": proposed,
        }
        return observations, rewards, terminated, truncated, infos

    def close(self, **kwargs: Any) -> None:
        """End the open streams (no failure learned), close the shield if the wrapper made
        it, then the environment."""
        for i in range(self.num_envs):
            if self._open[i]:
                self._end(i, self._z[i], None)
        if self._owned:
            self.shield.close()
        super().close(**kwargs)

    def _end(self, i: int, z: list[float] | None, event: str | None) -> dict[str, Any]:
        assert z is not None
        self._open[i], self._event[i] = False, None
        done = self.shield.revise(
            z, None, stream=self.streams[i], done=True, event=event, learn=not self.evaluation
        )
        return done.to_dict()

    def _observe(self, observations: Any, infos: dict[str, Any], i: int) -> list[float]:
        key = self.observation_key
        z = infos[key][i] if key in infos and _present(infos, key, i) else observations[i]
        return [float(v) for v in np.asarray(z, dtype=np.float64).reshape(-1)]


def _one(infos: dict[str, Any], i: int) -> dict[str, Any]:
    """Copy ``i``'s info from a vectorised one (its keys where their ``_key`` mask holds)."""
    return {
        key: _one(value, i) if isinstance(value, dict) else value[i]
        for key, value in infos.items()
        if not key.startswith("_") and _present(infos, key, i)
    }


def _present(infos: dict[str, Any], key: str, i: int) -> bool:
    """Whether ``infos[key]`` holds a value for copy ``i`` (its ``_key`` mask, where given)."""
    return f"_{key}" not in infos or bool(infos[f"_{key}"][i])


def _masked(key: str, values: list[dict[str, Any] | None]) -> dict[str, Any]:
    """``values`` as Gymnasium puts per-copy info: an object array and its ``_key`` mask."""
    array = np.empty(len(values), dtype=object)
    array[:] = values
    return {key: array, f"_{key}": np.array([v is not None for v in values])}
