"""The core's compiled kernels, and warming their cache.

The per-step path runs as numba kernels compiled on first use and cached on disk beside their
modules (or in the user's cache when that is read-only). :func:`warm` runs a short closed loop
through the default shield and the paper's, so that every kernel the service calls is compiled
(or loaded from the cache) before the first request: the image build does it once, and
``python -m app serve`` does it before it listens.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Iterator
from dataclasses import dataclass
from types import ModuleType

import numpy as np
from numba.core.registry import CPUDispatcher

from app.core import (
    _kernels,
    belief,
    clustering,
    flags,
    lazy_tpm,
    local_risk,
    observation,
    reach,
    risk,
    step,
)
from app.core.config import ShieldConfig
from app.core.shield import Shield

MODULES: tuple[ModuleType, ...] = (_kernels, observation, clustering, belief, flags, lazy_tpm,
                                   local_risk, reach, risk, step)


@dataclass(frozen=True)
class WarmUp:
    """What :func:`warm` did: kernels compiled now (not found in the cache) and loaded from
    it, and the seconds it took."""

    compiled: int
    loaded: int
    seconds: float


def kernels() -> Iterator[CPUDispatcher]:
    """Every compiled kernel of the core, once (where it is defined, not where imported)."""
    for module in MODULES:
        for value in vars(module).values():
            if isinstance(value, CPUDispatcher) and value.py_func.__module__ == module.__name__:
                yield value


def warm() -> WarmUp:
    """Compile (or load) every kernel by running a small closed loop through each preset,
    with failures, episode ends, steps that only ask (``learn=False``) and a snapshot round
    trip."""
    start = time.perf_counter()
    for config in presets():
        shield = _drive(Shield(config))
        Shield.from_snapshot(shield.snapshot())
    compiled = loaded = 0
    for kernel in kernels():
        compiled += sum(kernel.stats.cache_misses.values())
        loaded += sum(kernel.stats.cache_hits.values())
    return WarmUp(compiled, loaded, time.perf_counter() - start)


def presets() -> tuple[ShieldConfig, ...]:
    """The default, the paper's reviser and its literal reading, each reviser active after one
    episode, so that a short loop reaches every path of the step."""
    return tuple(
        dataclasses.replace(config, reviser=dataclasses.replace(config.reviser,
                                                                activate_after_episodes=1))
        for config in (ShieldConfig(), ShieldConfig.paper(), ShieldConfig.paper_literal()))


def _drive(shield: Shield) -> Shield:
    """Episodes that end in each criterion's failure, then one without."""
    rng = np.random.default_rng(0)
    names = [c.name for c in shield.config.criteria]
    low = np.array(shield.config.observation.low)
    high = np.array(shield.config.observation.high)
    for episode in range(len(names) + 2):
        z = rng.uniform(low, high)
        for _ in range(20):
            z = np.clip(z + rng.normal(0, 0.05, z.size) * (high - low), low, high)
            action = float(rng.uniform(shield.config.action.low, shield.config.action.high))
            shield.step(z, action)
            shield.step(z, action, learn=False)
        event = names[episode] if episode < len(names) else None
        shield.step(z, None, event=event, done=True)
    return shield
