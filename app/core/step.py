"""A step of the model in two compiled calls: the per-step path of :meth:`Shield.apply`.

:func:`observe` normalises the observation, clusters it and recognises the belief (Eq. 1).
Between the two calls the shield grows its per-state tables when a state was made (and resets
a moved state's transitions, A16), which only Python does. :func:`learn_and_decide` then
learns the stream's previous step (its transition, Eqs. 3-4 on the lazy TPM, and its risk
label for the local model), counts the recognition and flags the state (A4) and, for a reviser
that decides in the compiled step, decides. Each kernel calls the kernels of the modules that
own the arrays, so every equation has one implementation; this module only orders them.

Each part hands the step one tuple of its arrays and settings (its ``arrays()``), laid out by
the module that owns them and unpacked by that module's kernels, so that no order of
arguments is kept by hand across modules. Plain tuples, not named ones: numba reads a plain
tuple's types from a fingerprint, a named one's through Python, which costs more than the
rest of the call.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
import numpy.typing as npt
from numba import njit

from app.core import flags, lazy_tpm, local_risk
from app.core.clustering import learn_and_recognise
from app.core.observation import normalise

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]


class Learned(NamedTuple):
    """What :func:`learn_and_decide` did, with the decision's arrays it filled."""

    needed: int  # TPM pool slots it lacked (then nothing changed: compact and call again)
    flag_changed: bool  # whether the recognised state's flag changed
    decided: bool  # whether the reviser decided (once a failure was learned)
    threshold: float  # the decision's limit on the total risk (app.core.risk.decide)
    worst: int  # the criterion the proposal risks most
    final: int  # the bin the rule applies
    kept: bool  # whether the rule keeps the proposal
    by_bin: FloatArray  # each action's risk per criterion
    verdicts: IntArray  # each bin's verdict (-1: ok)


@njit(cache=True)
def observe(
    x: FloatArray,
    space: Any,
    clusterer: Any,
    top: int,
    index: IntArray,
    prob: FloatArray,
    z: FloatArray,
) -> tuple[int, int, int, int]:
    """The observation ``x`` into the clustering space (``z``, by the observation space's
    settings, :meth:`~app.core.observation.ObservationSpace.arrays`), clustered (the
    clusterer's arrays, :meth:`~app.core.clustering.EvolvingClusterer.arrays`, room for one
    more state) and recognised (``index`` and ``prob``, top ``top``). Returns the update's
    kind, the state it touched, the belief's size and the recognised state (the most likely,
    the lowest index of equals)."""
    raw, scales, features = space
    normalise(x, raw, scales, features, z)
    kind, at, m = learn_and_recognise(z, clusterer, top, index, prob)
    return kind, at, m, index[np.argmax(prob[:m])]


@njit(cache=True)
def learn_and_decide(
    tpm: Any,
    flag_arrays: Any,
    model: Any,
    prev_index: IntArray,
    prev_prob: FloatArray,
    prev_z: FloatArray,
    index: IntArray,
    prob: FloatArray,
    z: FloatArray,
    at: Any,
    by_bin: FloatArray,
    verdicts: IntArray,
) -> tuple[int, bool, bool, float, int, int, bool]:
    """What a step learns, then the risk reviser's decision (:class:`Learned`'s first fields).

    The parts' tuples: the lazy TPM's (:meth:`~app.core.lazy_tpm.LazyTransitions.arrays`),
    the flags' (:meth:`~app.core.flags.StateFlags.arrays`) and the reviser's
    (:meth:`~app.core.revisers.Reviser.step_arrays`: the local risk model's tuple,
    :meth:`~app.core.local_risk.LocalRisk.arrays`, then the decision's safe steps, threshold
    and margin). The step's: the stream's previous belief and observation, this step's, and
    ``at``: the recognised state, whether the stream entered it, the event (a criterion, -1:
    none), whether the episode ended, the stream's slot, the bins to learn the transition and
    the risk label under (-1: none), whether to decide and the proposal's bin. The decision
    fills ``by_bin`` and ``verdicts``.
    """
    recognised, entered, event, done, slot, transition_bin, risk_bin, decide, proposed_bin = at
    local, safe, threshold, margin = model
    if transition_bin >= 0:
        needed = lazy_tpm.learn(tpm, transition_bin, prev_index, prev_prob, index, prob)
        if needed:
            return needed, False, False, 0.0, 0, 0, False
    any_failure = local_risk.learn_outcome(
        local, slot, prev_index, prev_prob, prev_z, risk_bin, event, done, z
    )
    table, failures, rate, min_rate = flag_arrays
    changed = flags.observe(table, failures, recognised, event, entered, rate, min_rate)
    if not decide or not any_failure:
        return 0, changed, False, 0.0, 0, 0, False
    limit, worst, final, kept = local_risk.decide_step(
        local, index, prob, z, safe, proposed_bin, threshold, margin, by_bin, verdicts
    )
    return 0, changed, True, limit, worst, final, kept
