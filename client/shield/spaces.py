"""A shield configuration derived from an environment's spaces, and checked against them.

The core knows nothing of Gymnasium; this is where a ``Box`` becomes an
:class:`~app.core.ShieldConfig` and where a configuration written by hand is checked against
the environment it will guard, so that a mismatch fails at construction with the field at
fault instead of at the first step (or never).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
import numpy.typing as npt

from app.core import ActionSpec, Bound, Criterion, ObservationSpec, ShieldConfig
from app.core.config import MIN_SPAN

DEFAULT_BINS = 20
SAMPLE_MARGIN = 0.1  # a sample's range widens by this share of its span on each side
AnyEnv = gym.Env[Any, Any] | gym.vector.VectorEnv[Any, Any, Any]


class SpaceMismatch(ValueError):
    """A shield configuration or an action space that does not fit the environment."""

    def __init__(self, message: str, field: str) -> None:
        super().__init__(f"{field}: {message}")
        self.field = field


def one_dimensional(space: gym.Space[Any]) -> gym.spaces.Box:
    """The action space, if the shield can revise it: a Box of one finite number."""
    if not isinstance(space, gym.spaces.Box):
        raise SpaceMismatch(
            f"the shield revises a continuous Box action, not {space}", "action_space"
        )
    if int(np.prod(space.shape)) != 1:
        raise SpaceMismatch(
            f"the shield revises one action dimension; this action has shape {space.shape}. "
            "Shield one dimension (wrap the environment so that the others are fixed or "
            "chosen by the controller alone) or use one shield model per dimension",
            "action_space",
        )
    if not (np.isfinite(space.low).all() and np.isfinite(space.high).all()):
        raise SpaceMismatch("the action's bounds must be finite", "action_space")
    return space


def spaces(env: AnyEnv) -> tuple[gym.Space[Any], gym.Space[Any]]:
    """The action and observation spaces of ``env``, or of each copy of a vectorised one."""
    if isinstance(env, gym.vector.VectorEnv):
        return env.single_action_space, env.single_observation_space
    return env.action_space, env.observation_space


def own_config(env: AnyEnv) -> ShieldConfig | None:
    """The configuration an environment gives for its shield (a ``shield_config()`` method of
    the unwrapped environment, or of the first copy of a ``SyncVectorEnv``), if it has one. The
    copies of an ``AsyncVectorEnv`` live in other processes: pass their configuration."""
    if isinstance(env, gym.vector.VectorEnv):
        copies = getattr(env, "envs", None)
        if not copies:
            return None
        env = copies[0]
    own = getattr(env.unwrapped, "shield_config", None)
    return own() if callable(own) else None


def config_for(
    env: AnyEnv,
    criteria: Mapping[str, str | None | tuple[str | None, Bound]] | None = None,
    *,
    bins: int = DEFAULT_BINS,
    low: Sequence[float] | None = None,
    high: Sequence[float] | None = None,
    observations: npt.ArrayLike | None = None,
    base: ShieldConfig | None = None,
) -> ShieldConfig:
    """The shield configuration for ``env`` (or for each copy of a vectorised ``env``).

    An environment that knows its shield (a ``shield_config()`` method on the unwrapped
    environment, as ``CarFollowing-v0`` has) gives its own. Otherwise the action range is cut
    into ``bins`` bins, and ``criteria`` names each failure with the direction of the action
    that moves away from it: ``{"crash": "decrease"}`` (slower is safer), or None where that
    depends on the state (``{"fall": None}``: the shield learns it), and, where a failure
    is one observation number crossing a value, where it fails:
    ``{"crash": ("decrease", Bound("x0", below=0.0))}`` (the observation's numbers are named
    ``x0``, ``x1``, ...). Everything else is ``base`` (default: the shield's defaults).

    The shield scales every observation number by the range it normally takes, so that no
    number dominates the clustering's distances. Each number's range is, first found first:
    ``low``/``high`` (one bound per number); the range of ``observations`` (a sample of what
    the shield will see, one row per step, e.g. from :func:`sample_observations`) widened by
    :data:`SAMPLE_MARGIN` of its span on each side; the observation space's bounds. A number
    whose range is still infinite (an observation space declared ``Box(-inf, inf)``) is
    refused with :class:`SpaceMismatch` on ``observation_space``. Numbers outside the range
    are not clipped: the range only sets the scale.
    """
    action_space, space = spaces(env)
    action = one_dimensional(action_space)
    if criteria is None and low is None and high is None and observations is None:
        own = own_config(env)
        if own is not None:
            return own
    if not criteria and isinstance(env, gym.vector.VectorEnv) and not getattr(env, "envs", None):
        raise SpaceMismatch(
            "the copies of this vectorised environment live in other "
            "processes, where their own shield configuration cannot be read: "
            "pass config= (their shield_config(), say) or criteria=",
            "config",
        )
    if not criteria:
        raise SpaceMismatch(
            "name the failures and the action's direction away from each, "
            "e.g. criteria={'crash': 'decrease'}",
            "criteria",
        )
    if not isinstance(space, gym.spaces.Box):
        raise SpaceMismatch(f"the shield observes a Box, not {space}", "observation_space")
    size = int(np.prod(space.shape))
    lows = np.asarray(space.low, np.float64).reshape(-1)
    highs = np.asarray(space.high, np.float64).reshape(-1)
    if observations is not None:
        lows, highs = sample_range(observations, size)
    for name, given in (("low", low), ("high", high)):
        if given is not None and np.shape(given) != (size,):
            raise SpaceMismatch(
                f"{name} needs one bound per observation number ({size}), not {np.shape(given)}",
                name,
            )
    lows = lows if low is None else np.asarray(low, np.float64)
    highs = highs if high is None else np.asarray(high, np.float64)
    unbounded = [i for i in range(size) if not (np.isfinite(lows[i]) and np.isfinite(highs[i]))]
    if unbounded:
        which = (
            f"all {size} of its numbers"
            if len(unbounded) == size
            else f"numbers {unbounded} of its {size} (flattened)"
        )
        raise SpaceMismatch(
            f"the observation space {space} leaves {which} unbounded, and the shield scales "
            "every number by the range it normally takes: give it, config_for(env, criteria, "
            "low=[...], high=[...]) with one bound per number, or let a sample of "
            "observations give it, config_for(env, criteria, "
            "observations=sample_observations(env)), then ShieldWrapper(env, config=...)",
            "observation_space",
        )
    a_low, a_high = float(action.low.reshape(-1)[0]), float(action.high.reshape(-1)[0])
    base = base or ShieldConfig()
    return dataclasses.replace(
        base,
        observation=ObservationSpec(
            names=tuple(f"x{i}" for i in range(size)),
            low=tuple(lows.tolist()),
            high=tuple(highs.tolist()),
            knee=(),
        ),
        action=ActionSpec(low=a_low, high=a_high, step=(a_high - a_low) / bins),
        criteria=tuple(
            Criterion(name, *(how if isinstance(how, tuple) else (how,)))
            for name, how in criteria.items()
        ),
    )


def sample_range(
    observations: npt.ArrayLike, size: int
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Each observation number's range in a sample (rows of ``size`` numbers, or of any shape
    holding ``size``), widened by :data:`SAMPLE_MARGIN` of its span on each side; a number
    that never varied, or by less than the narrowest range a configuration accepts, gets a
    span of its magnitude (at least 1)."""
    try:
        sample = np.asarray(observations, dtype=np.float64)
    except (TypeError, ValueError) as error:
        raise SpaceMismatch(
            f"a sample of observations is an array of numbers ({error})", "observations"
        ) from error
    if sample.ndim == 0 or sample.size == 0 or sample.size % size:
        raise SpaceMismatch(
            f"a sample of observations holds rows of the observation's {size} "
            f"numbers; this one has shape {sample.shape}",
            "observations",
        )
    sample = sample.reshape(-1, size)
    if not np.isfinite(sample).all():
        raise SpaceMismatch(
            "the sample of observations holds numbers that are not finite", "observations"
        )
    lows, highs = sample.min(axis=0), sample.max(axis=0)
    span = highs - lows  # (one narrower than the configuration accepts counts as none)
    span = np.where(span >= MIN_SPAN, span, np.maximum(np.abs(lows), 1.0))
    return lows - SAMPLE_MARGIN * span, highs + SAMPLE_MARGIN * span


def sample_observations(
    env: gym.Env[Any, Any],
    steps: int = 1000,
    seed: int = 0,
    observation_key: str = "efsm_observation",
) -> npt.NDArray[np.float64]:
    """What the shield would see over ``steps`` steps of random actions (the action space's
    own samples, seeded by ``seed``), one row per step: ``info[observation_key]`` where the
    environment gives one, else the observation. For :func:`config_for`'s ``observations``
    where the observation space does not bound them; a sample from your own controller covers
    the range it will meet better."""
    if steps < 1:
        raise ValueError("steps must be >= 1")
    env.action_space.seed(seed)
    observation, info = env.reset(seed=seed)
    rows = [info.get(observation_key, observation)]
    while len(rows) < steps:
        observation, _, terminated, truncated, info = env.step(env.action_space.sample())
        rows.append(info.get(observation_key, observation))
        if (terminated or truncated) and len(rows) < steps:
            observation, info = env.reset()
            rows.append(info.get(observation_key, observation))
    return np.array([np.asarray(row, np.float64).reshape(-1) for row in rows])


def check_config(
    config: ShieldConfig, env: AnyEnv, observation_key: str = "efsm_observation"
) -> None:
    """Raise :class:`SpaceMismatch` where ``config`` cannot guard ``env``: actions the
    environment would not accept, or observations of another size (checked here when the
    environment shows the shield its observation itself and lives in this process, at the
    first reset otherwise)."""
    action_space, space = spaces(env)
    action = one_dimensional(action_space)
    a_low, a_high = float(action.low.reshape(-1)[0]), float(action.high.reshape(-1)[0])
    tolerance = 1e-6 * max(1.0, a_high - a_low)
    if config.action.low < a_low - tolerance:
        raise SpaceMismatch(
            f"{config.action.low} lies below the environment's {a_low}", "action.low"
        )
    if config.action.high > a_high + tolerance:
        raise SpaceMismatch(
            f"{config.action.high} lies above the environment's {a_high}", "action.high"
        )
    remote = isinstance(env, gym.vector.VectorEnv) and not getattr(env, "envs", None)
    if not remote and own_config(env) is None and isinstance(space, gym.spaces.Box):
        check_observation(config, int(np.prod(space.shape)), observation_key)


def check_observation(config: ShieldConfig, size: int, observation_key: str) -> None:
    """Raise :class:`SpaceMismatch` unless the shield's observations hold ``size`` numbers."""
    if size != config.observation.size:
        raise SpaceMismatch(
            f"the configuration observes {config.observation.size} numbers "
            f"({', '.join(config.observation.names)}), the environment shows {size} "
            f"(its observation, or info[{observation_key!r}] where it gives one)",
            "observation.names",
        )
