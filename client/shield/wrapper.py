"""The shield as a Gymnasium wrapper: any environment with a one-dimensional Box action.

    env = ShieldWrapper(gym.make("client.sim:CarFollowing-v0"))          # the paper's world
    env = ShieldWrapper(gym.make("Pendulum-v1"), failure=overspeed,
                        config=config_for(pendulum, {"overspeed_cw": "increase",
                                                     "overspeed_ccw": "decrease"}))

Each step sends the shield what the environment shows it (``info[observation_key]`` when the
environment provides one, else the observation), the proposed action and the failure the
previous step ended in, and gives the environment the shield's action. Failures come from
``failure(observation, reward, terminated, truncated, info)`` or from ``info[event_key]``, at
any step: a failure that does not end the episode is learned all the same.

A wrapper that sees :data:`SILENT_EPISODES` episodes terminate without one failure reported
warns once (:class:`NoFailureReported`): the environment most likely reports its failures
under another key (highway-env's ``info["crashed"]``), and the shield would learn nothing.

``info`` carries, JSON-able: ``shield`` (the decision record), ``applied_action`` (what the
environment was given, in its action's shape), ``proposed_action``, ``shield_observation``, and
at the end of an episode ``shield_done``. Learning controllers should learn from the applied
action (:class:`client.shield.sb3.AppliedActionReplayBuffer` does it for SB3's off-policy
algorithms).

A wrapped environment is not :func:`gymnasium.utils.env_checker.check_env`-deterministic: the
same seed and actions give other ``info`` (and, once it revises, other transitions) as the
shield learns. ``set_evaluation(True)`` stops learning (the model answers as it is).
"""

from __future__ import annotations

import inspect
import itertools
import os
import warnings
from collections.abc import Callable, Mapping
from typing import Any

import gymnasium as gym
import numpy as np

from app.core import ShieldConfig
from client.shield.base import StepShield
from client.shield.local import LocalShield
from client.shield.spaces import (
    AnyEnv,
    check_config,
    check_observation,
    config_for,
    one_dimensional,
)

Failure = Callable[[Any, float, bool, bool, dict[str, Any]], str | None]
_copies = itertools.count()
SILENT_EPISODES = 3  # terminated episodes without a failure reported before the warning


class NoFailureReported(UserWarning):
    """Episodes terminate and not one failure has reached the shield: it learns nothing."""


class FailureWatch:
    """Warns once, with :class:`NoFailureReported`, when :data:`SILENT_EPISODES` episodes
    have terminated (truncations do not count) and no failure was reported at any step: the
    shield learns which actions lead to failures, and here it would learn nothing, silently.
    An environment whose episodes end well (a goal reached) warns too; the message says how
    to silence it."""

    def __init__(
        self, failure: Failure | None, event_key: str, config: ShieldConfig | None
    ) -> None:
        self.failure = failure
        self.event_key = event_key
        self.names = [c.name for c in config.criteria] if config is not None else []
        self.terminated = 0
        self.reported = False
        self.key_seen = False  # info[event_key] was present at some step
        self.warned = False

    def step(self, event: str | None, terminated: bool, info: Mapping[str, Any]) -> None:
        """Count one step's outcome; warn if it makes the failures' silence suspicious."""
        self.key_seen = self.key_seen or self.event_key in info
        self.reported = self.reported or bool(event)
        self.terminated += terminated
        if self.warned or self.reported or self.terminated < SILENT_EPISODES:
            return
        self.warned = True
        warnings.warn(self.message(), NoFailureReported, stacklevel=3)

    def message(self) -> str:
        """What the warning says: what was seen and how to pass ``failure=``."""
        name = self.names[0] if self.names else "crash"
        if self.failure is None:
            source = (
                f"It reads failures from info[{self.event_key!r}], which this environment "
                f"{'has always left empty' if self.key_seen else 'never sets'}. "
            )
        else:
            source = "Its failure= predicate returned None at every step. "
        criteria = f" (this shield's criteria: {', '.join(self.names)})" if self.names else ""
        return (
            f"{self.terminated} episodes terminated and the shield was told of no failure in "
            f"any of them, so it learns nothing to avoid. {source}If the environment reports "
            "its failures elsewhere (highway-env: info['crashed']), pass failure=, called "
            "after every step as failure(observation, reward, terminated, truncated, info) "
            f"and returning the name of the criterion that failed{criteria}, or None: "
            f"ShieldWrapper(env, failure=lambda observation, reward, terminated, truncated, "
            f"info: {name!r} if info.get('crashed') else None, ...). If these episodes ended "
            "well, ignore this: warnings.filterwarnings('ignore', "
            "category=client.shield.NoFailureReported)."
        )


def check_failure(failure: Failure | None) -> None:
    """Refuse a ``failure`` predicate that cannot take the five arguments it is called with."""
    if failure is None:
        return
    try:
        signature = inspect.signature(failure)
    except (TypeError, ValueError):  # a callable whose signature Python cannot read
        return
    try:
        signature.bind(None, 0.0, False, False, {})
    except TypeError as error:
        raise TypeError(
            f"failure= is called after every step as failure(observation, reward, terminated, "
            f"truncated, info) and returns the failed criterion's name or None; "
            f"{getattr(failure, '__name__', failure)}{signature} cannot take these five "
            f"arguments ({error})"
        ) from error


def reported(
    failure: Failure | None,
    event_key: str,
    observation: Any,
    reward: float,
    terminated: bool,
    truncated: bool,
    info: dict[str, Any],
) -> str | None:
    """The failure a step ended in: ``failure(...)``'s answer, else ``info[event_key]``."""
    if failure is None:
        event: Any = info.get(event_key)
        return None if event is None else str(event)
    event = failure(observation, reward, terminated, truncated, info)
    if event is not None and not isinstance(event, str):
        raise TypeError(
            f"failure= returns the name of the criterion that failed (a str) or None, not {event!r}"
        )
    return event


def bind(
    env: AnyEnv,
    shield: StepShield | None,
    config: ShieldConfig | None,
    criteria: Mapping[str, str] | None,
    observation_key: str,
    warmup_steps: int,
) -> tuple[ShieldConfig | None, StepShield]:
    """The configuration (derived from ``env`` and ``criteria`` unless given, and checked
    against ``env``) and the shield a wrapper uses: ``shield``, or a :class:`LocalShield` of
    its own."""
    if warmup_steps < 0:
        raise ValueError("warmup_steps must be >= 0")
    if shield is None and config is None:
        config = config_for(env, criteria)
    if config is not None:
        check_config(config, env, observation_key)
    return config, shield if shield is not None else LocalShield(config)


def reseeded(config: ShieldConfig | None, seed: int) -> tuple[ShieldConfig, LocalShield]:
    """``config`` with the reviser's seed from a ``reset(seed=...)``, and a fresh shield."""
    base = (config or ShieldConfig()).to_dict()
    config = ShieldConfig.from_dict({**base, "reviser": {**base["reviser"], "seed": seed % 2**63}})
    return config, LocalShield(config)


def default_stream() -> str:
    """A name per wrapper, distinct across the copies of a vectorised environment, in one
    process or many."""
    return f"env-{os.getpid()}-{next(_copies)}"


class ShieldWrapper(gym.Wrapper[Any, Any, Any, Any]):
    """Revise every proposed action before the environment sees it.

    ``shield`` is any :class:`~client.shield.base.StepShield` (a service client, a WebSocket
    session, a :class:`LocalShield`); without one, the wrapper keeps a :class:`LocalShield` of
    its own, built from ``config`` (default: :func:`config_for` the environment, with
    ``criteria``) and seeded by the first ``reset(seed=...)``. A shield passed in is the
    caller's to close; one the wrapper made, the wrapper closes.

    Failures come from ``failure(observation, reward, terminated, truncated, info)`` (the
    name of the criterion that failed, or None) where given, else from ``info[event_key]``;
    see :class:`FailureWatch` for the warning when none ever comes.

    ``warmup_steps``: the shield learns and reports but does not change the action for this
    many steps of this wrapper. ``shadow``: never change it.
    """

    def __init__(
        self,
        env: gym.Env[Any, Any],
        shield: StepShield | None = None,
        *,
        config: ShieldConfig | None = None,
        criteria: Mapping[str, str] | None = None,
        failure: Failure | None = None,
        event_key: str = "event",
        observation_key: str = "efsm_observation",
        stream: str | None = None,
        warmup_steps: int = 0,
        shadow: bool = False,
    ) -> None:
        super().__init__(env)
        one_dimensional(env.action_space)
        check_failure(failure)
        self._owned = shield is None
        self.config, self.shield = bind(
            env, shield, config, criteria, observation_key, warmup_steps
        )
        self.failure = failure
        self.event_key = event_key
        self.watch = FailureWatch(failure, event_key, self.config)
        self.observation_key = observation_key
        self.stream = stream if stream is not None else default_stream()
        self.warmup_steps = warmup_steps
        self.shadow = shadow
        self.evaluation = False
        self.steps = 0  # this wrapper's steps, for the warm-up
        self._seeded = False
        self._z: list[float] | None = None
        self._open = False  # a step of this episode reached the shield
        self._event: str | None = None  # a failure not yet told, learned on the next step

    def set_evaluation(self, on: bool = True) -> None:
        """Evaluation mode: the shield still revises but learns nothing (``learn: false``)."""
        self.evaluation = on

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        if self._open:  # an episode left mid-way: its stream ends here, no failure learned
            self._end(self._z, None)
        if seed is not None and self._owned and not self._seeded and self.steps == 0:
            self._seeded = True
            self.shield.close()
            self.config, self.shield = reseeded(self.config, seed)
        observation, info = self.env.reset(seed=seed, options=options)
        self._z = self._observe(observation, info)
        if self.config is not None:
            check_observation(self.config, len(self._z), self.observation_key)
        self._event = None
        return observation, info

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        if self._z is None:
            raise gym.error.ResetNeeded("call reset() before step()")
        proposed = float(np.asarray(action, dtype=np.float64).reshape(-1)[0])
        z = self._z
        shadow = self.shadow or self.steps < self.warmup_steps
        decision = self.shield.revise(
            z,
            proposed,
            stream=self.stream,
            event=self._event,
            shadow=shadow,
            learn=not self.evaluation,
        )
        self._open, self._event = True, None
        self.steps += 1
        assert decision.action is not None
        space = self.env.action_space
        applied = np.asarray(decision.action, dtype=space.dtype).reshape(space.shape)
        observation, reward, terminated, truncated, info = self.env.step(applied)
        event = reported(
            self.failure, self.event_key, observation, float(reward), terminated, truncated, info
        )
        self.watch.step(event, terminated, info)
        self._z = self._observe(observation, info)
        info["shield"] = decision.to_dict()
        info["applied_action"] = applied
        info["proposed_action"] = proposed
        info["shield_observation"] = z
        if terminated or truncated:
            info["shield_done"] = self._end(self._z, event)
        else:
            self._event = event
        return observation, float(reward), terminated, truncated, info

    def close(self) -> None:
        """End the open episode's stream (no failure learned), close the shield if the wrapper
        made it, then the environment."""
        if self._open:
            self._end(self._z, None)
        if self._owned:
            self.shield.close()
        super().close()

    def _end(self, z: list[float] | None, event: str | None) -> dict[str, Any]:
        assert z is not None
        self._open, self._event = False, None
        done = self.shield.revise(
            z, None, stream=self.stream, done=True, event=event, learn=not self.evaluation
        )
        return done.to_dict()

    def _observe(self, observation: Any, info: dict[str, Any]) -> list[float]:
        z = info.get(self.observation_key, observation)
        return [float(v) for v in np.asarray(z, dtype=np.float64).reshape(-1)]
