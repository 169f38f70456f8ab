"""The core's compiled kernels: keeping their cache true to the sources, and warming it.

The per-step path runs as numba kernels compiled on first use and cached on disk beside their
modules (or in ``NUMBA_CACHE_DIR``, or the user's cache when that is read-only). Numba checks a
cached kernel against its own module's source only, while a kernel holds the compiled code of
the callees it calls in other modules: after an edit to ``reach.py`` alone,
``step.learn_and_decide`` would load from the cache and run the old ``reach.risk``.
:func:`keep_cache_current` closes that gap at import (``app.core`` calls it before any kernel
runs): the cache carries a fingerprint of every source of the core, and where the sources no
longer match it, the core's cached kernels are deleted and compile again.

:func:`warm` runs a short closed loop through the default shield and the paper's, so that every
kernel the service calls is compiled (or loaded from the cache) before the first request: the
image build does it once, and ``python -m app serve`` does it before it listens.
"""

from __future__ import annotations

import dataclasses
import hashlib
import logging
import os
import tempfile
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
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

MODULES: tuple[ModuleType, ...] = (
    _kernels,
    observation,
    clustering,
    belief,
    flags,
    lazy_tpm,
    local_risk,
    reach,
    risk,
    step,
)
STAMP = "core-sources.sha256"  # the fingerprint's file, in each folder of the cache

log = logging.getLogger(__name__)


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


def fingerprint() -> str:
    """The sha256 of every source of the core (any of them may hold what a kernel compiles
    in: a callee, a constant)."""
    digest = hashlib.sha256()
    for source in sorted(Path(__file__).parent.glob("*.py")):
        digest.update(source.name.encode())
        digest.update(source.read_bytes())
    return digest.hexdigest()


IMPORTED = fingerprint()  # the sources as this process imported them: the core it runs


def version() -> str:
    """The core this process runs, named by the first 12 digits of its sources' fingerprint
    (experiment records, bench results and ``GET /healthz`` carry it)."""
    return IMPORTED[:12]


def cache_folders() -> set[Path]:
    """The folders where numba keeps the core's kernels (one, unless the modules moved)."""
    # (numba has no public name for it: its cache's folder, as its locator chose it)
    return {
        Path(kernel._cache._cache_path)  # type: ignore[attr-defined]
        for kernel in kernels()
    }


def keep_cache_current() -> list[Path]:
    """Delete the core's cached kernels wherever the cache's fingerprint is not the sources'
    (:func:`fingerprint`), then stamp it; returns the folders cleared. A folder that cannot
    be written is left as it is, with a warning: its kernels may be older than the sources."""
    current = IMPORTED
    stems = tuple(f"{module.__name__.rpartition('.')[2]}." for module in MODULES)
    cleared = []
    for folder in sorted(cache_folders()):
        stamp = folder / STAMP
        try:
            if stamp.read_text() == current:
                continue
        except OSError:
            pass  # no fingerprint yet: a new cache, or one written before fingerprints
        try:
            folder.mkdir(parents=True, exist_ok=True)
            for path in folder.iterdir():
                if path.name.startswith(stems) and path.suffix in (".nbi", ".nbc"):
                    path.unlink(missing_ok=True)
            with tempfile.NamedTemporaryFile("w", dir=folder, delete=False) as file:
                file.write(current)
            os.replace(file.name, stamp)
        except OSError as error:
            log.warning(
                "the compiled core's cache in %s cannot be refreshed (%s): its kernels "
                "may be older than their sources; set NUMBA_CACHE_DIR to a writable "
                "folder",
                folder,
                error,
            )
            continue
        log.info(
            "the core's sources differ from its compiled cache in %s: its kernels compile again",
            folder,
        )
        cleared.append(folder)
    return cleared


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
        dataclasses.replace(
            config, reviser=dataclasses.replace(config.reviser, activate_after_episodes=1)
        )
        for config in (ShieldConfig(), ShieldConfig.paper(), ShieldConfig.paper_literal())
    )


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
