"""Failure-aware risk per action over a horizon: the risk reviser (``reviser.method: risk``).

The paper flags *states* where a failure was seen and steers away from them. That attaches a
failure to the wrong thing: a crash in a state happened under an action, and braking there a
thousand times without a crash says nothing about accelerating there. This module keeps, per
(state, action bin), how often the action was applied, where it led and which failures it ended
in, and turns those counts into the probability of each failure within H steps:

* **Outcomes.** ``p_c(s, a) = F_c(s, a) / (N(s, a) + beta)`` is the posterior mean of failure
  ``c`` under a prior of ``beta`` safe pseudo-tries (so one failure in one try reads 1 / (1 +
  beta), and the estimate shrinks only as *that* action is tried there again);
  ``P(j | s, a) = T(s, a, j) / (N(s, a) + beta)`` the move to state ``j``.
* **Horizon.** Finite-horizon value iteration, as probabilistic shields compute it:
  ``Q_h(s, a) = p(s, a) + sum_j P(j | s, a) V_{h-1}(j)`` with ``V_h(s) = Q_h(s, a*)`` for the
  action ``a*`` of least total risk (the safest continuation), ``V_0 = 0``. An action never
  tried there counts at its monotone lower bound (below): the shield can choose it, and then
  learns what it does, so a state where the controller braked too late does not look doomed
  while a harder braking is still untried.
* **Monotone prior.** Each criterion has a safe direction: braking harder never raises the risk
  of a collision, speeding up never raises the risk of falling behind. So the risk of an action
  is at least that of every action on its safe side: ``Q`` is replaced by its running maximum
  from the safe end of the action range, which also gives an action never tried in a state the
  risk of the riskiest tried one on its safe side.

The table ``Q`` (states x actions x criteria) is refreshed at episode ends and every
``refresh_steps`` steps; a step only reads it: ``risk(a) = sum_i belief_i Q(i, a)``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt
from numba import njit

from app.core import _stored as stored
from app.core._arrays import ensure_capacity, read_only
from app.core.errors import InvalidSnapshot

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]


class OutcomeCounts:
    """Per (state, action bin): tries, failures per criterion, and moves to each next state.

    Moves are sparse: one entry per (state, action, next state) seen, found through a dict, so
    a model of thousands of states stores only the transitions that happened.
    """

    def __init__(self, n_actions: int, n_criteria: int, max_states: int) -> None:
        self.n_actions = n_actions
        self.n_criteria = n_criteria
        self.max_states = max_states
        self._n = 0
        self._tries = np.zeros((0, n_actions), dtype=np.int64)
        self._failures = np.zeros((0, n_actions, n_criteria), dtype=np.int64)
        self._rows = np.zeros(0, dtype=np.int64)  # s * q + a
        self._cols = np.zeros(0, dtype=np.int64)  # next state j
        self._moves = np.zeros(0, dtype=np.int64)
        self._m = 0
        self._where: dict[int, int] = {}
        self._n_failures = 0  # kept so that the per-step check does not scan the counts
        self.version = 0  # counts of steps learned; the risk table compares it

    @property
    def n_states(self) -> int:
        """Number of states counted for."""
        return self._n

    @property
    def tries(self) -> IntArray:
        """How often each action was applied in each state, n x q (read-only view)."""
        return read_only(self._tries[: self._n])

    @property
    def failures(self) -> IntArray:
        """Failures per criterion that each (state, action) ended in, n x q x C (read-only)."""
        return read_only(self._failures[: self._n])

    @property
    def any_failure(self) -> bool:
        """Whether a failure has been counted at all."""
        return self._n_failures > 0

    def moves(self) -> tuple[IntArray, IntArray, IntArray]:
        """The sparse moves: row ``s * q + a``, next state ``j``, count (read-only views)."""
        m = self._m
        return (read_only(self._rows[:m]), read_only(self._cols[:m]),
                read_only(self._moves[:m]))

    def add_state(self) -> None:
        """A new state starts untried."""
        n = self._n
        self._tries = ensure_capacity(self._tries, n + 1, self.max_states)
        self._failures = ensure_capacity(self._failures, n + 1, self.max_states)
        self._n = n + 1

    def learn_move(self, state: int, action_bin: int, next_state: int) -> None:
        """Action ``action_bin`` applied in ``state`` led to ``next_state``."""
        self._tries[state, action_bin] += 1
        row = state * self.n_actions + action_bin
        key = row * self.max_states + next_state
        at = self._where.get(key)
        if at is None:
            at = self._m
            self._rows = ensure_capacity(self._rows, at + 1, 1 << 62)
            self._cols = ensure_capacity(self._cols, at + 1, 1 << 62)
            self._moves = ensure_capacity(self._moves, at + 1, 1 << 62)
            self._rows[at], self._cols[at] = row, next_state
            self._where[key] = at
            self._m = at + 1
        self._moves[at] += 1
        self.version += 1

    def learn(self, state: int, action_bin: int, next_state: int, criterion: int | None
              ) -> None:
        """Either outcome: a move to ``next_state``, or (``criterion`` given) a failure."""
        if criterion is None:
            self.learn_move(state, action_bin, next_state)
        else:
            self.learn_failure(state, action_bin, criterion)

    def learn_failure(self, state: int, action_bin: int, criterion: int) -> None:
        """Action ``action_bin`` applied in ``state`` ended in a failure of ``criterion``."""
        self._tries[state, action_bin] += 1
        self._failures[state, action_bin, criterion] += 1
        self._n_failures += 1
        self.version += 1

    def snapshot(self) -> dict[str, Any]:
        """Exact state as arrays."""
        rows, cols, moves = self.moves()
        return {"tries": self.tries.copy(), "failures": self.failures.copy(),
                "rows": rows.copy(), "cols": cols.copy(), "moves": moves.copy(),
                "version": self.version}

    @classmethod
    def restore(cls, n_actions: int, n_criteria: int, max_states: int,
                data: dict[str, Any]) -> OutcomeCounts:
        """Rebuild from :meth:`snapshot` output, checking every index and count."""
        tries = stored.ints(data["tries"], "outcomes.tries")
        n = tries.shape[0] if tries.ndim == 2 else -1
        if tries.shape != (n, n_actions) or n > max_states:
            raise InvalidSnapshot("outcome tries must be states x actions",
                                  field="outcomes.tries")
        failures = stored.ints(data["failures"], "outcomes.failures", (n, n_actions, n_criteria))
        rows = stored.ints(data["rows"], "outcomes.rows", high=max(n * n_actions - 1, 0)).ravel()
        cols = stored.ints(data["cols"], "outcomes.cols", rows.shape, high=max(n - 1, 0))
        moves = stored.ints(data["moves"], "outcomes.moves", rows.shape, low=1)
        moved = np.zeros(n * n_actions, dtype=np.int64)
        np.add.at(moved, rows, moves)
        if (moved.reshape(n, n_actions) + failures.sum(axis=2) != tries).any():
            raise InvalidSnapshot("outcome tries are not the sum of moves and failures",
                                  field="outcomes.tries")
        self = cls.from_arrays(n_actions, n_criteria, max_states, tries, failures, rows, cols,
                               moves, stored.integer(data["version"], "outcomes.version"))
        if len(self._where) != rows.size:
            raise InvalidSnapshot("outcome moves repeat a (state, action, next state)",
                                  field="outcomes.rows")
        return self

    @classmethod
    def from_arrays(cls, n_actions: int, n_criteria: int, max_states: int, tries: IntArray,
                    failures: IntArray, rows: IntArray, cols: IntArray, moves: IntArray,
                    version: int) -> OutcomeCounts:
        """Counts made elsewhere (a snapshot, a recount), taken as they are."""
        self = cls(n_actions, n_criteria, max_states)
        self._tries, self._failures, self._n = tries, failures, tries.shape[0]
        self._rows, self._cols, self._moves, self._m = rows, cols, moves, rows.size
        self._where = {int(r) * max_states + int(c): i
                       for i, (r, c) in enumerate(zip(rows, cols, strict=True))}
        self._n_failures = int(failures.sum())
        self.version = version
        return self


def horizon_risk(
    tries: IntArray,
    failures: IntArray,
    moves: tuple[IntArray, IntArray, IntArray],
    directions: Sequence[str],
    horizon: int,
    prior_safe: float,
) -> FloatArray:
    """``Q_H``: per state, action and criterion, the probability of that failure within
    ``horizon`` steps when the action is applied now and the safest action after (an untried
    one at its monotone bound).

    >>> tries = np.array([[1, 1], [0, 0]])          # state 0: each of two actions tried once
    >>> failures = np.array([[[0], [1]], [[0], [0]]])  # action 1 crashed
    >>> moves = (np.array([0]), np.array([1]), np.array([1]))  # action 0 went to state 1
    >>> horizon_risk(tries, failures, moves, ["decrease"], 1, 1.0)[0, :, 0].tolist()
    [0.0, 0.5]
    """
    rows, cols, counts = moves
    out = np.empty(failures.shape)
    _horizon_risk(np.ascontiguousarray(tries, dtype=np.int64),
                  np.ascontiguousarray(failures, dtype=np.int64),
                  np.ascontiguousarray(rows, dtype=np.int64),
                  np.ascontiguousarray(cols, dtype=np.int64),
                  np.ascontiguousarray(counts, dtype=np.int64),
                  safe_steps(directions), horizon, prior_safe, out)
    return out


def safe_steps(directions: Sequence[str]) -> IntArray:
    """Per criterion, the way along the action bins that never raises its risk: -1 where
    slower is safer (``decrease``), +1 where faster is (``increase``)."""
    return np.array([-1 if d == "decrease" else 1 for d in directions], dtype=np.int64)


@njit(cache=True)
def monotone(q_table: FloatArray, safe: IntArray, out: FloatArray
             ) -> None:
    """``out``: the running maximum of each criterion's risk from its safe end of the action
    range (``safe`` from :func:`safe_steps`).

    Slower is safer (collision): ``Q(s, a) >= Q(s, a')`` for every ``a' < a``; faster is
    safer (falling behind): for every ``a' > a``. An action never tried in a state (risk 0
    of its own) so takes the risk of the riskiest tried action on its safe side, the nearest
    one included.
    """
    n, q, n_c = q_table.shape
    for s in range(n):
        for c in range(n_c):
            first, last, way = (0, q, 1) if safe[c] < 0 else (q - 1, -1, -1)
            running = q_table[s, first, c]
            for a in range(first, last, way):
                value = q_table[s, a, c]
                running = value if value > running else running
                out[s, a, c] = running


@njit(cache=True)
def _horizon_risk(tries: IntArray, failures: IntArray, rows: IntArray, cols: IntArray,
                  counts: IntArray, safe: IntArray, horizon: int, prior_safe: float,
                  out: FloatArray) -> None:
    """:func:`horizon_risk` into ``out``: value iteration on the counts.

    ``Q_h(s, a) = p(s, a) + sum_j P(j | s, a) V_{h-1}(j)``, V the risk of the action of least
    total risk (tried or not: an untried one at its monotone lower bound, which the shield
    may choose), 0 where nothing was tried; the moves are summed in the order counted.
    """
    n, q, n_c = failures.shape
    p_fail = np.empty((n, q, n_c))  # posterior mean of each failure
    tried = np.zeros(n, dtype=np.bool_)
    for s in range(n):
        for a in range(q):
            denominator = tries[s, a] + prior_safe
            tried[s] |= tries[s, a] > 0
            for c in range(n_c):
                p_fail[s, a, c] = failures[s, a, c] / denominator
    p_move = np.empty(rows.shape[0])
    for m in range(rows.shape[0]):
        p_move[m] = counts[m] / (tries[rows[m] // q, rows[m] % q] + prior_safe)
    monotone(p_fail, safe, out)
    value = np.zeros((n, n_c))
    ahead = np.empty((n * q, n_c))
    work = np.empty((n, q, n_c))
    for _ in range(horizon - 1):
        for s in range(n):
            best, least = 0, math.inf
            for a in range(q):
                total = out[s, a, 0]
                for c in range(1, n_c):
                    total += out[s, a, c]
                if total < least:
                    best, least = a, total
            for c in range(n_c):
                value[s, c] = out[s, best, c] if tried[s] else 0.0
        ahead[:] = 0.0
        for m in range(rows.shape[0]):
            for c in range(n_c):
                ahead[rows[m], c] += p_move[m] * value[cols[m], c]
        for s in range(n):
            for a in range(q):
                for c in range(n_c):
                    work[s, a, c] = p_fail[s, a, c] + ahead[s * q + a, c]
        monotone(work, safe, out)


@njit(cache=True)
def kept_limit(total: FloatArray, threshold: float, margin: float
               ) -> float:
    """The largest total risk an action may carry and be applied: ``threshold``, or ``margin``
    above the safest action's risk, whichever is higher."""
    least: float = total.min()
    return max(threshold, least + margin)


@njit(cache=True)
def choose(total: FloatArray, proposed_bin: int, limit: float, safe_step: int
           ) -> int:
    """The bin to apply: the proposal when its total risk is within ``limit``
    (:func:`kept_limit`); otherwise the allowed bin nearest to it, ties broken towards
    ``safe_step`` (-1: slower, +1: faster)."""
    if total[proposed_bin] <= limit:
        return proposed_bin
    best, best_distance = -1, 0
    for a in range(total.shape[0]):
        if total[a] <= limit:
            offset = a - proposed_bin
            distance = abs(offset) * 2 - (1 if (offset > 0) - (offset < 0) == safe_step else 0)
            if best < 0 or distance < best_distance:
                best, best_distance = a, distance
    return best


@njit(cache=True)
def decide(table: FloatArray, index: IntArray, prob: FloatArray, proposed_bin: int,
           threshold: float, margin: float, safe: IntArray, by_bin: FloatArray,
           verdicts: IntArray) -> tuple[float, int, int, bool]:
    """One step of the risk reviser on the table: ``by_bin`` (actions x criteria) gets the
    risk under the belief, ``sum_i belief_i Q(i, a)``, and ``verdicts`` each bin's: -1 within
    the limit (:func:`kept_limit`), else its riskiest criterion (the first of equals).
    Returns the limit, the proposal's verdict, the bin to apply (:func:`choose`, towards the
    safe side of the proposal's riskiest criterion) and whether that is the proposal because
    it is within the limit."""
    q, n_c = by_bin.shape
    total = np.empty(q)
    for a in range(q):
        for c in range(n_c):
            risk = 0.0
            for i in range(index.shape[0]):
                risk += prob[i] * table[index[i], a, c]
            by_bin[a, c] = risk
        total[a] = by_bin[a, 0]
        for c in range(1, n_c):
            total[a] += by_bin[a, c]
    limit = kept_limit(total, threshold, margin)
    for a in range(q):
        worst = 0
        for c in range(1, n_c):
            if by_bin[a, c] > by_bin[a, worst]:
                worst = c
        verdicts[a] = -1 if total[a] <= limit else worst
    kept = total[proposed_bin] <= limit
    worst = verdicts[proposed_bin]
    if kept:
        return limit, worst, proposed_bin, kept
    return limit, worst, choose(total, proposed_bin, limit, safe[worst]), kept
