"""A model as plain data and numpy arrays, and back: :func:`take` and :func:`restore`.

A snapshot holds the configuration, the counters and the history, the e-FSM (clustering,
transition matrices, flags), each stream's previous step, and the reviser's part
(:meth:`app.core.revisers.Reviser.snapshot`). Every part is checked before it is used
(:mod:`app.core._stored`): sizes against the configuration, numbers finite and in range,
probabilities in [0, 1] and beliefs summing to 1, counts no larger than the learning steps
that made them. Formats 2 and 3 restore too (CHANGELOG.md says what each added).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from app.core import _stored as stored
from app.core.belief import Belief
from app.core.clustering import EvolvingClusterer
from app.core.config import ShieldConfig
from app.core.errors import InvalidConfig, InvalidSnapshot, ShieldError
from app.core.flags import StateFlags
from app.core.history import History
from app.core.lazy_tpm import LazyTransitions
from app.core.stream import Counters, StreamState
from app.core.tpm import DenseTransitions
from app.core.trial import AUDITED, NONE

if TYPE_CHECKING:
    from app.core.shield import Shield

FORMAT = 4


def take(shield: Shield) -> dict[str, Any]:
    """Everything ``shield`` is, as plain data and numpy arrays."""
    counters = shield.counters
    return {
        "format": FORMAT,
        "config": shield.config.to_dict(),
        "counters": {
            "steps": counters.steps,
            "episodes": counters.episodes,
            "model_version": counters.model_version,
            "interventions": dict(counters.interventions),
            "failures": dict(counters.failures),
            "streams_expired": counters.streams_expired,
        },
        "history": shield.history.snapshot(),
        "clustering": shield.clusterer.snapshot(),
        "transitions": shield.transitions.snapshot(),
        "flags": shield.flags.snapshot(),
        **shield.reviser.snapshot(),
        "streams": {
            name: {
                "index": None if s.belief is None else s.belief.index.copy(),
                "prob": None if s.belief is None else s.belief.prob.copy(),
                "applied_bin": s.applied_bin,
                "proposed_bin": s.proposed_bin,
                "step": s.step,
                "z": None if s.z is None else s.z.copy(),
                "arm": s.arm,
                "failed": s.failed,
            }
            for name, s in shield.streams.items()
        },
    }


def restore(
    cls: type[Shield], data: dict[str, Any], check: Callable[[ShieldConfig], None] | None = None
) -> Shield:
    """A ``cls`` that makes exactly the decisions the snapshot's model would make.

    ``check`` (a server's bounds) judges the configuration before any array is built; its
    :class:`InvalidConfig` is refused like the configuration's own. Anything missing,
    malformed or inconsistent raises :class:`InvalidSnapshot` naming the field."""
    if not isinstance(data, dict) or data.get("format") not in (2, 3, FORMAT):
        raise InvalidSnapshot(f"expected snapshot format {FORMAT}", field="format")
    try:
        return _restore(cls, data, check)
    except InvalidConfig as error:
        raise InvalidSnapshot(
            f"its configuration: {error.message}",
            field=f"config.{error.field}" if error.field else "config",
        ) from error
    except ShieldError:
        raise
    except (
        KeyError,
        TypeError,
        ValueError,
        IndexError,
        OverflowError,
        AttributeError,
    ) as error:
        raise InvalidSnapshot(f"snapshot is incomplete or inconsistent: {error!r}") from error


def _restore(
    cls: type[Shield], data: dict[str, Any], check: Callable[[ShieldConfig], None] | None
) -> Shield:
    config = ShieldConfig.from_stored(data["config"])
    if check is not None:
        check(config)
    shield = cls(config)
    cfg = shield.config
    counters = data["counters"]
    steps = stored.integer(counters["steps"], "counters.steps", high=stored.MAX_COUNT)
    shield.counters = Counters(
        steps=steps,
        episodes=stored.integer(counters["episodes"], "counters.episodes", high=steps),
        model_version=stored.integer(
            counters["model_version"], "counters.model_version", high=stored.MAX_COUNT
        ),
        interventions={
            c.name: stored.integer(
                counters["interventions"][c.name],
                f"counters.interventions.{c.name}",
                high=steps,
            )
            for c in cfg.criteria
        },
        streams_expired=stored.integer(
            counters.get("streams_expired", 0), "counters.streams_expired", high=steps
        ),
    )
    limit = cfg.limits.max_states
    shield.clusterer = EvolvingClusterer.restore(
        cfg.clustering, shield.space.size, limit, data["clustering"]
    )
    tpm = data["transitions"]
    if tpm["backend"] != cfg.limits.tpm_backend:
        raise InvalidSnapshot(
            f"the matrices are {tpm['backend']!r}, the configuration's "
            f"backend {cfg.limits.tpm_backend!r}",
            field="transitions.backend",
        )
    if tpm["backend"] == "dense":
        shield.transitions = DenseTransitions.restore(cfg.action.n_bins, cfg.transitions, tpm)
    else:
        shield.transitions = LazyTransitions.restore(cfg.action.n_bins, cfg.transitions, limit, tpm)
    shield.flags = StateFlags.restore(
        cfg.reviser.flags, limit, len(cfg.criteria), cfg.reviser.flag_min_rate, data["flags"]
    )
    n = shield.clusterer.n_states
    if shield.transitions.n_states != n or shield.flags.flags.shape[0] != n:
        raise InvalidSnapshot("states, matrices and flags disagree on the state count")
    _restore_history(shield, data)
    streams = data["streams"]
    if len(streams) > cfg.limits.max_streams:
        raise InvalidSnapshot(f"more than {cfg.limits.max_streams} streams", field="streams")
    shield.streams = {
        str(name): _restore_stream(shield, f"streams.{name}", s, slot)
        for slot, (name, s) in enumerate(streams.items())
    }
    shield.reviser.restore(data)
    _check_counts(shield)
    return shield


def _check_counts(shield: Shield) -> None:
    """Refuse counts beyond the learning steps behind them: each learning step clusters one
    observation (``clustering.k``), which one state absorbs (its support and visits), and the
    reviser learns it once (:meth:`app.core.revisers.Reviser.counted`)."""
    steps, clusterer, flags = shield.counters.steps, shield.clusterer, shield.flags
    k = clusterer.k

    def total(counts: npt.NDArray[np.int64]) -> float:  # (in floats: no sum overflows)
        return float(counts.sum(dtype=np.float64))

    parts: list[tuple[str, float, int]] = [
        ("clustering.k", k, steps),
        ("clustering.capacity_hits", clusterer.capacity_hits, k),
        ("clustering.support", total(clusterer.support), k),
        ("flags.visits", total(flags.visits), steps),
        ("counters.failures", sum(shield.counters.failures.values()), steps),
        *((name, count, steps) for name, count in shield.reviser.counted()),
    ]
    for field_name, count, most in parts:
        if count > most:
            raise InvalidSnapshot(
                f"{count:.0f} counted, more than the {most} learning steps behind it",
                field=field_name,
            )
    if (flags.entries > flags.visits).any():
        raise InvalidSnapshot("a state entered more often than visited", field="flags.entries")
    if (flags.failures.sum(axis=1, dtype=np.float64) > flags.visits).any():
        raise InvalidSnapshot("a state's failures exceed its visits", field="flags.failures")


def _restore_history(shield: Shield, data: dict[str, Any]) -> None:
    """The failure counters and the history; a snapshot written before them (they are
    optional keys: older versions of the core ignore them) starts them from what it holds:
    the failures its states counted, and one row of the totals now."""
    criteria = shield.config.criteria
    failures = data["counters"].get("failures")
    shield.counters.failures = (
        {c.name: int(f) for c, f in zip(criteria, shield.flags.failures.sum(axis=0), strict=True)}
        if failures is None
        else {
            c.name: stored.integer(failures[c.name], f"counters.failures.{c.name}")
            for c in criteria
        }
    )
    shield.history = History(len(criteria))
    if data.get("history") is not None:
        shield.history = History.restore(len(criteria), data["history"], shield.totals())
    elif shield.counters.episodes:
        shield.history.record(shield.totals())


def _restore_stream(shield: Shield, field: str, data: dict[str, Any], slot: int) -> StreamState:
    """One stream's state in ``slot``, its belief and bins checked against the model's
    sizes."""
    if not 1 <= len(field) - len("streams.") <= 128:
        raise InvalidSnapshot("stream names have 1 to 128 characters", field=field)
    n = shield.n_states
    belief = None
    if data["index"] is not None:
        index = stored.ints(data["index"], f"{field}.index", high=n - 1).ravel()
        prob = stored.floats(data["prob"], f"{field}.prob", index.shape, low=0.0, high=1.0)
        if not index.size or np.unique(index).size != index.size:
            raise InvalidSnapshot("a belief names distinct states", field=f"{field}.index")
        stored.distribution(prob, f"{field}.prob")
        belief = Belief(index, prob)
    q = shield.config.action.n_bins
    return StreamState(
        slot,
        belief,
        stored.integer(data["applied_bin"], f"{field}.applied_bin", high=q - 1),
        stored.integer(data["proposed_bin"], f"{field}.proposed_bin", high=q - 1),
        stored.integer(data["step"], f"{field}.step", high=shield.counters.steps),
        -1 if belief is None else belief.argmax(),
        None
        if belief is None or data.get("z") is None
        else stored.floats(data["z"], f"{field}.z", (shield.space.size,)),
        # (a snapshot from before the trial: no episode in it)
        stored.integer(data.get("arm", NONE), f"{field}.arm", low=NONE, high=AUDITED),
        stored.boolean(data.get("failed", False), f"{field}.failed"),
    )
