"""What a person reads of a model: its states, one state, the failure points its reviser keeps,
the totals over its episodes and the transitions out of a state. Plain data and arrays, built
on request from a :class:`~app.core.shield.Shield` (the service turns them into JSON)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from app.core.belief import Belief
from app.core.history import EPISODES, N_STATES, STEPS, TOTALS
from app.core.record import COLUMNS as RECORD_COLUMNS

if TYPE_CHECKING:
    from app.core.shield import Shield

FloatArray = npt.NDArray[np.float64]


def states(shield: Shield) -> dict[str, Any]:
    """Every state: centre in physical units, spread (normalised std), flag, visits,
    entries, failures (states x criteria), and the reviser's own record there and whether it
    backs off there (:mod:`app.core.record`)."""
    clusterer, flags = shield.clusterer, shield.flags
    names = [None, *shield.reviser.names]
    return {
        "centre": shield.physical(clusterer.centres),
        "spread": np.sqrt(clusterer.variances()),
        "flag": [names[f] for f in flags.flags],
        "visits": flags.visits.copy(),
        "entries": flags.entries.copy(),
        "failures": flags.failures.copy(),
        "support": clusterer.support,
        "record": shield.reviser.record_counts(),
        "backed_off": shield.reviser.backed_off(),
    }


def state(shield: Shield, index: int) -> dict[str, Any]:
    """One state: centre in physical units, spread, flag, visits, entries, failures by
    criterion, and the reviser's own record there (:mod:`app.core.record`)."""
    clusterer, flags, reviser = shield.clusterer, shield.flags, shield.reviser
    names = [None, *reviser.names]
    failures = flags.failures[index]
    return {
        "index": index,
        "centre": [float(v) for v in shield.physical(clusterer.centres[index])],
        "spread": float(np.sqrt(clusterer.variances()[index])),
        "flag": names[int(flags.flags[index])],
        "visits": int(flags.visits[index]),
        "entries": int(flags.entries[index]),
        "failures": {c: int(f) for c, f in zip(reviser.names, failures, strict=True)},
        "record": dict(zip(RECORD_COLUMNS, reviser.record_counts()[index].tolist(), strict=True)),
        "backed_off": reviser.backs_off(index),
    }


def failure_points(shield: Shield) -> dict[str, FloatArray]:
    """Per criterion, the observations (physical units) where the reviser keeps its failures
    (the reach, :mod:`app.core.reach`): none without one."""
    reviser = shield.reviser
    return {
        name: shield.physical(reviser.failure_points(c)) for c, name in enumerate(reviser.names)
    }


def history(shield: Shield) -> dict[str, Any]:
    """The totals at the end of episodes (:mod:`app.core.history`), one list per column,
    and the totals now."""
    names = shield.reviser.names
    rows, k, c = shield.history.rows, len(names), shield.counters
    return {
        "stride": shield.history.stride,
        "limit": shield.history.limit,
        "episodes": rows[:, EPISODES].tolist(),
        "steps": rows[:, STEPS].tolist(),
        "n_states": rows[:, N_STATES].tolist(),
        "interventions": {n: rows[:, TOTALS + i].tolist() for i, n in enumerate(names)},
        "failures": {n: rows[:, TOTALS + k + i].tolist() for i, n in enumerate(names)},
        "totals": {
            "episodes": c.episodes,
            "steps": c.steps,
            "n_states": shield.n_states,
            "model_version": c.model_version,
            "interventions": dict(c.interventions),
            "failures": dict(c.failures),
        },
    }


def next_states(shield: Shield, index: int, top: int) -> list[list[tuple[int, float]]]:
    """For each action, the ``top`` most likely next states of ``index`` (row of Eq. 2)."""
    one_hot = Belief(np.array([index]), np.array([1.0]))
    out = []
    for a in range(shield.config.action.n_bins):
        row = shield.transitions.predict(one_hot, a, True)  # P^T e_i = row i
        best = np.argsort(-row, kind="stable")[:top]
        out.append([(int(j), float(row[j])) for j in best])
    return out
