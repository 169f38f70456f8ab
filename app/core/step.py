"""A step of the model in two compiled calls: the per-step path of :meth:`Shield.apply`.

:func:`observe` normalises the observation, clusters it and recognises the belief (Eq. 1).
Between the two calls the shield grows its per-state tables when a state was made (and resets
a moved state's transitions, A16), which only Python does. :func:`learn_and_decide` then
learns the stream's previous step (its transition, Eqs. 3-4 on the lazy TPM, and its risk
label for the local model), counts the recognition and flags the state (A4) and, for the risk
reviser, decides. Each kernel calls the kernels of the modules that own the arrays, so every
equation has one implementation; this module only orders them, on the arrays the modules hand
out (``arrays()``), so that a step passes a few dozen arrays to two calls instead of many
small calls from Python.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from numba import njit

from app.core import flags, lazy_tpm, local_risk, reach
from app.core.clustering import learn_and_recognise
from app.core.observation import normalise

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
ColArray = npt.NDArray[np.int32]


@njit(cache=True)
def observe(
    x: FloatArray,
    raw: bool,
    scales: FloatArray,
    features: FloatArray,
    z: FloatArray,
    centres: FloatArray,
    stats: FloatArray,
    support: IntArray,
    sums: FloatArray,
    counts: IntArray,
    params: FloatArray,
    modes: IntArray,
    top: int,
    index: IntArray,
    prob: FloatArray,
) -> tuple[int, int, int, int]:
    """The observation ``x`` into the clustering space (``z``), clustered (the clusterer's
    arrays, room for one more state) and recognised (``index`` and ``prob``, top ``top``).
    Returns the update's kind, the state it touched, the belief's size and the recognised
    state (the most likely, the lowest index of equals)."""
    normalise(x, raw, scales, features, z)
    kind, at, m = learn_and_recognise(
        z, centres, stats, support, sums, counts, params, modes, top, index, prob
    )
    return kind, at, m, index[np.argmax(prob[:m])]


@njit(cache=True)
def learn_and_decide(
    lr: float,
    log_decay: FloatArray,
    numbers: FloatArray,
    row_counts: IntArray,
    pool_cols: ColArray,
    pool_vals: FloatArray,
    used: IntArray,
    slots: IntArray,
    horizon: int,
    theta: FloatArray,
    cov: FloatArray,
    tried: IntArray,
    low: FloatArray,
    high: FloatArray,
    extent: FloatArray,
    midpoints: FloatArray,
    queue_index: IntArray,
    queue_prob: FloatArray,
    queue_phi: FloatArray,
    queue_ends: IntArray,
    failures: IntArray,
    dynamics: FloatArray,
    dynamics_cov: FloatArray,
    peak: FloatArray,
    points: FloatArray,
    point_counts: IntArray,
    bounds: FloatArray,
    flag_table: IntArray,
    flag_failures: IntArray,
    rate: bool,
    min_rate: float,
    safe: IntArray,
    threshold: float,
    margin: float,
    reach_horizon: int,
    reach_radius: float,
    prev_index: IntArray,
    prev_prob: FloatArray,
    prev_z: FloatArray,
    index: IntArray,
    prob: FloatArray,
    z: FloatArray,
    recognised: int,
    entered: bool,
    event: int,
    done: bool,
    slot: int,
    transition_bin: int,
    risk_bin: int,
    decide: bool,
    proposed_bin: int,
    by_bin: FloatArray,
    verdicts: IntArray,
) -> tuple[int, bool, bool, float, int, int, bool]:
    """What a step learns, then the risk reviser's decision.

    The arguments come in groups: the lazy TPM's (:meth:`LazyTransitions.arrays`, after its
    learning rate), the local risk model's (:meth:`LocalRisk.arrays`, after its horizon, with
    the reach's), the flags' (:meth:`StateFlags.arrays`, then its mode and rate), the
    decision's settings (the reach's horizon last but one: 0 without it); then
    the step's: the stream's previous belief and observation, this step's belief and
    observation, the recognised state and whether the stream entered it, the event (a
    criterion, -1: none), whether the episode ended, the stream's slot, the bins to learn the
    transition and the risk label under (-1: none), whether to decide, the proposal's bin and
    the decision's outputs (``by_bin``, ``verdicts``).

    Returns the TPM pool slots it lacks (then nothing has changed: the shield compacts the
    pool and calls again), whether a flag changed, whether it decided (the risk reviser,
    once a failure was learned), and the decision (:func:`app.core.risk.decide`).
    """
    if transition_bin >= 0:
        needed = lazy_tpm.learn(
            transition_bin,
            lr,
            prev_index,
            prev_prob,
            index,
            prob,
            log_decay,
            numbers,
            row_counts,
            pool_cols,
            pool_vals,
            used,
            slots,
        )
        if needed:
            return needed, False, False, 0.0, 0, 0, False
    if risk_bin >= 0:
        local_risk.learn_step(
            theta,
            cov,
            tried,
            low,
            high,
            extent,
            midpoints,
            queue_index,
            queue_prob,
            queue_phi,
            queue_ends,
            failures,
            slot,
            prev_index,
            prev_prob,
            prev_z,
            risk_bin,
            event,
            done,
            horizon,
        )
        if reach_horizon > 0:
            phi = np.empty(prev_z.shape[0] + 2)
            phi[0], phi[1:-1], phi[-1] = 1.0, prev_z, midpoints[risk_bin]
            reach.learn(dynamics, dynamics_cov, peak, prev_index, prev_prob, phi, z)
    if event >= 0 and reach_horizon > 0:
        reach.add_failure(points, point_counts, event, z, reach_radius)
    changed = flags.observe(flag_table, flag_failures, recognised, event, entered, rate, min_rate)
    if not decide or not failures.any():
        return 0, changed, False, 0.0, 0, 0, False
    limit, worst, final, kept = local_risk.decide_step(
        theta,
        tried,
        low,
        high,
        index,
        prob,
        z,
        midpoints,
        safe,
        proposed_bin,
        threshold,
        margin,
        by_bin,
        verdicts,
        dynamics,
        peak,
        extent,
        points,
        point_counts,
        bounds,
        reach_horizon,
        reach_radius,
    )
    return 0, changed, True, limit, worst, final, kept
