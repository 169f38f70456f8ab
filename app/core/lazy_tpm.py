"""The TPMs of Eqs. 3-4 in a lazy form whose memory and per-step cost do not grow as n^2.

Write ``D_a = (1 - phi)^u_a`` for the decay after ``u_a`` updates of action ``a``. Unrolling
Eqs. 3-4 with epsilon-bar padding gives, for every entry of ``F^a``:

    F^a(i, j) = D_a * (eps * g_a(max(i, j)) + S_a(i, j)),   g_a(m) = 1 / D_a(when m appeared)

The first term is the padding, which depends only on when states appeared; the second is what
was learned, ``S_a = sum_t phi tau_t gamma_t^T / D_a(t)``, sparse because beliefs are truncated
to their top-k states. Rows are normalised on demand: ``P^a(i, .) = F^a(i, .) / F_o^a(i)``.

The learned entries of every row of every action live in one pool: a row is a contiguous run
``[start, start + cap)`` of which the first ``nnz`` slots are used, in the order learned. A
row that fills moves to the pool's end with twice its room, and a full pool is compacted into
one of twice the live size, so memory follows what was learned (not the widest row times n)
and a step never copies more than the rows it touches, amortised.

Scales live in the log domain (``lg_a(m) = log g_a(m)``, ``ld_a = log D_a``) and each learned row
keeps its own offset, so nothing overflows or underflows to 0/0 over millions of steps: the
stable form of Eqs. 3-4 (docs/algorithm.md) without its dense rows. Only the rows a belief
touches are read or written; a prediction costs O(k W + n) for k belief states and W stored
entries per row.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt
from numba import njit

from app.core import _kernels
from app.core import _stored as stored
from app.core._arrays import ensure_capacity
from app.core._kernels import NEG_INF, logaddexp, pairwise_sum
from app.core.belief import Belief
from app.core.config import TransitionConfig
from app.core.errors import InvalidSnapshot
from app.core.tpm import marginal_by_action

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
ColArray = npt.NDArray[np.int32]


class LazyTransitions:
    """All TPMs of one model: padding in closed form, learned mass in sparse rows."""

    def __init__(self, n_actions: int, config: TransitionConfig, max_states: int) -> None:
        self.config = config
        self.n_actions = n_actions
        self.max_states = max_states
        self._n = 0
        q = n_actions
        self._log_decay = np.zeros(q)  # ld_a = log D_a
        self._created = np.zeros((q, 0))  # lg_a(m) = -ld_a when state m appeared
        self._pad = np.zeros((q, 0))  # exp(lg_a(m) - lg_a(n-1)), prior mode
        self._pad_tail = np.zeros((q, 1))  # sum_{j >= m} pad_a(j), with a trailing 0
        # Per row (action x state), in one array each so that a compiled step takes them
        # whole: the numbers (offset: learned row i is exp(offset) * vals; row_sum: the sum
        # of vals; then, kept so that neither learning nor prediction recomputes the row
        # normaliser F_o of every belief state, log of the padding mass / D_a and of the
        # padding level, and P^a(i, .) = learned_scale(i) * vals(i) + pad_scale(i) *
        # padding(i)) and the counts (entries, the row's run in the pool: start and room)
        self._rows = np.zeros((6, q, 0))
        self._row_counts = np.zeros((3, q, 0), dtype=np.int64)
        self._views()
        self._pool_cols: ColArray = np.zeros(0, dtype=np.int32)
        self._pool_vals: FloatArray = np.zeros(0)
        self._used = np.zeros(1, dtype=np.int64)  # pool slots handed out to rows
        self._arrays: tuple[Any, ...] | None = None  # see arrays
        self._log_prior = math.log(config.prior)
        self._scratch = np.zeros(0, dtype=np.int64)  # see _learn

    def _views(self) -> None:
        """Name the rows of the per-row arrays (again after they grow)."""
        (
            self._offset,
            self._row_sum,
            self._log_pad,
            self._log_level,
            self._learned_scale,
            self._pad_scale,
        ) = self._rows
        self._nnz, self._start, self._cap = self._row_counts

    @property
    def n_states(self) -> int:
        """Current matrix size n."""
        return self._n

    def arrays(self) -> tuple[Any, ...]:
        """What a compiled step learns a transition with (:func:`learn`'s ``tpm``): the
        learning rate, then the log decay, the per-row numbers and counts, the pool's columns
        and values, its use and a scratch map; the same tuple until a state is added or the
        pool is compacted."""
        if self._arrays is None:
            self._arrays = (
                self.config.learning_rate,
                self._log_decay,
                self._rows,
                self._row_counts,
                self._pool_cols,
                self._pool_vals,
                self._used,
                self._scratch,
            )
        return self._arrays

    def add_state(self) -> None:
        """Expand every matrix by one state: the new pads are ``eps`` at today's scale."""
        n, limit = self._n, self.max_states
        self._created = ensure_capacity(self._created, n + 1, limit, axis=1)
        self._pad = ensure_capacity(self._pad, n + 1, limit, axis=1)
        self._pad_tail = ensure_capacity(self._pad_tail, n + 2, limit + 1, axis=1)
        self._rows = ensure_capacity(self._rows, n + 1, limit, axis=2)
        self._row_counts = ensure_capacity(self._row_counts, n + 1, limit, axis=2)
        self._views()
        if self._scratch.shape[0] < n + 1:
            self._scratch = np.zeros(limit, dtype=np.int64)
        self._arrays = None
        self._created[:, n] = -self._log_decay
        self._offset[:, n] = -self._log_decay
        self._n = n + 1
        self._refresh()

    def _refresh(self) -> None:
        """Recompute what depends on the state count: the padding and every row's scales."""
        n = self._n
        if n == 0:
            return
        created = self._created[:, :n]
        mode = self.config.expansion
        if mode == "prior":
            self._pad[:, :n] = _kernels.exp(created - created[:, n - 1 : n])
            self._pad_tail[:, :n] = np.cumsum(self._pad[:, n - 1 :: -1], axis=1)[:, ::-1]
            self._pad_tail[:, n] = 0.0
            level = self._log_prior + created[:, n - 1 : n]
            pad_mass = self._pad[:, :n] * np.arange(1, n + 1) + self._pad_tail[:, 1 : n + 1]
            self._log_level[:, :n] = level
            self._log_pad[:, :n] = level + _kernels.log(pad_mass)
        else:
            self._log_level[:, :n] = self._log_prior + created
            self._log_pad[:, :n] = self._log_level[:, :n]
            if mode == "zero_uniform":
                self._log_pad[:, :n] += _kernels.log(np.arange(1.0, n + 1))
        at = np.s_[:, :n]
        self._refresh_scales(at, self._offset[at], self._row_sum[at])

    def _refresh_scales(self, at: Any, offset: Any, row_sum: FloatArray) -> None:
        """Row i of P^a is ``learned_scale(i) * vals(i) + pad_scale(i) * padding(i)``, for the
        rows ``at`` whose offsets and learned sums are given (one implementation with the
        learning kernel's, :func:`_row_scales`, so that a restored row scales as learned)."""
        self._learned_scale[at], self._pad_scale[at] = _scales(
            self._log_pad[at], self._log_level[at], offset, row_sum
        )

    def learn_one(self, prev: Belief, action_bin: int, belief: Belief) -> None:
        """Eqs. 3-4 with tau = prev, gamma = belief, for the matrix of ``action_bin``.

        ``F <- (1 - phi) F + phi tau gamma^T`` becomes ``D <- (1 - phi) D`` and
        ``S += phi tau gamma^T / D``; touched rows are first re-based to the new scale.
        """
        while True:
            needed = learn(
                self.arrays(), action_bin, prev.index, prev.prob, belief.index, belief.prob
            )
            if not needed:
                return
            self.compact(needed)

    def compact(self, extra: int) -> None:
        """Move every row, in action and state order, into a pool of twice the live room
        plus ``extra`` (rows keep their room)."""
        n = self._n
        live = int(self._cap[:, :n].sum())
        size = max(2 * (live + extra), 64)
        cols = np.zeros(size, dtype=np.int32)
        vals = np.zeros(size)
        self._used[0] = _compact(
            self._start[:, :n],
            self._cap[:, :n],
            self._nnz[:, :n],
            self._pool_cols,
            self._pool_vals,
            cols,
            vals,
        )
        self._pool_cols, self._pool_vals = cols, vals
        self._arrays = None

    def _entries(self, a: int) -> tuple[IntArray, ColArray, FloatArray]:
        """Action ``a``'s learned entries in row order, each row's in the order learned:
        rows, columns and values."""
        n = self._n
        nnz = self._nnz[a, :n]
        rows = np.repeat(np.arange(n), nnz)
        at = np.repeat(self._start[a, :n], nnz) + (
            np.arange(rows.size) - np.repeat(np.cumsum(nnz) - nnz, nnz)
        )
        return rows, self._pool_cols[at], self._pool_vals[at]

    def predict(self, belief: Belief, action_bin: int, transpose: bool) -> FloatArray:
        """Eq. 5: ``P^T p`` when ``transpose`` (A1), else the literal ``P p``."""
        if transpose:
            return self._predict_transposed(belief, action_bin)
        return self._predict_literal(belief, action_bin)

    def _predict_transposed(self, belief: Belief, a: int) -> FloatArray:
        n, rows, p = self._n, belief.index, belief.prob
        learned = p * self._learned_scale[a][rows]
        pred = np.zeros(n)
        _add_learned(
            rows, learned, self._start[a], self._nnz[a], self._pool_cols, self._pool_vals, pred
        )
        c = p * self._pad_scale[a][rows]
        mode = self.config.expansion
        if mode == "prior":
            # sum_i c_i pad(max(i, j)) = pad(j) sum_{i<j} c_i + sum_{i>=j} c_i pad(i)
            below = np.zeros(rows.size + 1)
            c.cumsum(out=below[1:])
            weighted = _suffix_sums(c * self._pad[a][rows])
            segment = belief.segments(n)
            pred += self._pad[a][:n] * below.repeat(segment) + weighted.repeat(segment)
        elif mode == "zero_uniform":  # row i spreads over columns j <= i
            pred += _suffix_sums(c).repeat(belief.segments(n))
        else:
            pred[rows] += c
        return pred

    def predict_marginal(self, belief: Belief, transpose: bool) -> FloatArray:
        """Eq. 7's step: Eq. 5 under the marginal TPM, ``(1/q) sum_r P^r``.

        The transposed form runs every action at once, with the arithmetic of
        :meth:`predict` per action and the same sum in action order, so that it gives the
        numbers of :func:`marginal_by_action` bit for bit at a fraction of the cost (the
        two-step prediction makes q predictions per inspected action).
        """
        if not transpose:
            return marginal_by_action(self, belief, transpose)
        n, q, rows, p = self._n, self.n_actions, belief.index, belief.prob
        learned = p * self._learned_scale[:, rows]  # (q, k)
        pred = np.zeros((q, n))
        for a in range(q):  # each action's entries summed in the order its own would be
            _add_learned(
                rows,
                learned[a],
                self._start[a],
                self._nnz[a],
                self._pool_cols,
                self._pool_vals,
                pred[a],
            )
        c = p * self._pad_scale[:, rows]
        mode = self.config.expansion
        if mode == "prior":
            below = np.zeros((q, rows.size + 1))
            c.cumsum(axis=1, out=below[:, 1:])
            weighted = _suffix_sums(c * self._pad[:, rows])
            segment = belief.segments(n)
            pred += self._pad[:, :n] * below.repeat(segment, axis=1) + weighted.repeat(
                segment, axis=1
            )
        elif mode == "zero_uniform":
            pred += _suffix_sums(c).repeat(belief.segments(n), axis=1)
        else:
            pred[:, rows] += c
        total = np.zeros(n)
        for row in pred:  # in action order, as marginal_by_action adds them
            total += row
        mean: FloatArray = total / q
        return mean

    def _predict_literal(self, belief: Belief, a: int) -> FloatArray:
        n = self._n
        p = belief.dense(n)
        pred = np.empty(n)
        _dot_rows(p, self._start[a], self._nnz[a], self._pool_cols, self._pool_vals, pred)
        pred *= self._learned_scale[a, :n]
        mode = self.config.expansion
        scale = self._pad_scale[a, :n]
        if mode == "prior":
            pad = self._pad[a, :n]
            at_or_below = np.cumsum(p)
            weighted = np.cumsum(p * pad)
            pred += scale * (pad * at_or_below + (weighted[-1] - weighted))
        else:
            pred += scale * (np.cumsum(p) if mode == "zero_uniform" else p)
        return pred

    def reset_row(self, state: int) -> None:
        """A16 ``reset``: drop the learned mass of a moved state; its padding stays."""
        for a in range(self.n_actions):
            start = self._start[a, state]
            self._pool_vals[start : start + self._nnz[a, state]] = 0.0
            self._nnz[a, state] = 0
            self._row_sum[a, state] = 0.0
            self._offset[a, state] = -self._log_decay[a]
        at = np.s_[:, state : state + 1]
        self._refresh_scales(at, self._offset[at], self._row_sum[at])

    def matrix(self, action_bin: int) -> FloatArray:
        """The dense n x n matrix of one action (for snapshots and tests)."""
        a, n = action_bin, self._n
        if n == 0:
            return np.zeros((0, 0))
        rows = np.arange(n)
        mode = self.config.expansion
        scale = self._pad_scale[a, :n]
        if mode == "prior":
            out: FloatArray = self._pad[a, np.maximum.outer(rows, rows)] * scale[:, None]
        else:
            shape = np.tril(np.ones((n, n))) if mode == "zero_uniform" else np.eye(n)
            out = shape * scale[:, None]
        at, cols, vals = self._entries(a)
        np.add.at(out, (at, cols), vals * self._learned_scale[a, at])
        return out

    def row_mass(self, action_bin: int) -> FloatArray:
        """``F_o`` of one action: the weighted departure count of every state (Eq. 4)."""
        a = action_bin
        if self._n == 0:
            return np.zeros(0)
        n = self._n
        log_norm = _log_norm(self._log_pad[a, :n], self._offset[a, :n], self._row_sum[a, :n])
        mass: FloatArray = _kernels.exp(self._log_decay[a] + log_norm)
        return mass

    def nbytes(self) -> int:
        """Memory held by the matrices."""
        arrays: list[npt.NDArray[Any]] = [
            self._created,
            self._pad,
            self._pad_tail,
            self._rows,
            self._row_counts,
            self._scratch,
            self._pool_cols,
            self._pool_vals,
        ]
        return sum(int(x.nbytes) for x in arrays)

    def snapshot(self) -> dict[str, Any]:
        """Exact state: scales plus the learned entries of every row, in slot order."""
        n = self._n
        actions = []
        for a in range(self.n_actions):
            _, cols, vals = self._entries(a)
            nnz = self._nnz[a, :n].copy()
            actions.append(
                {
                    "width": int(nnz.max(initial=0)),  # the widest row
                    "nnz": nnz,
                    "offset": self._offset[a, :n].copy(),
                    "row_sum": self._row_sum[a, :n].copy(),
                    "cols": cols,
                    "vals": vals,
                }
            )
        return {
            "backend": "lazy",
            "n_states": n,
            "log_decay": self._log_decay.copy(),
            "created": self._created[:, :n].copy(),
            "actions": actions,
        }

    @classmethod
    def restore(
        cls, n_actions: int, config: TransitionConfig, max_states: int, data: dict[str, Any]
    ) -> LazyTransitions:
        """Rebuild from :meth:`snapshot` output, bit for bit, every part checked."""
        self = cls(n_actions, config, max_states)
        n = stored.integer(data["n_states"], "transitions.n_states", high=max_states)
        q = n_actions
        self._n = n
        self._log_decay = stored.floats(data["log_decay"], "transitions.log_decay", (q,), high=0.0)
        self._created = stored.floats(data["created"], "transitions.created", (q, n))
        # every scale was -ld_a when it was set, and ld_a only falls: 0 <= scale <= -ld_a now,
        # and states appeared in order (an offset beyond would make a row's mass infinite)
        latest = -self._log_decay[:, None] * (1 + 1e-12) + 1e-12
        if ((self._created < 0) | (self._created > latest)).any() or (
            np.diff(self._created, axis=1) < 0
        ).any():
            raise InvalidSnapshot(
                "a state's creation lies outside the decays so far", field="transitions.created"
            )
        self._pad = np.zeros((q, n))
        self._pad_tail = np.zeros((q, n + 1))
        self._rows = np.zeros((6, q, n))
        self._row_counts = np.zeros((3, q, n), dtype=np.int64)
        self._views()
        self._scratch = np.zeros(max_states, dtype=np.int64)
        entries = data["actions"]
        pool_cols: list[ColArray] = []
        pool_vals: list[FloatArray] = []
        if not isinstance(entries, list) or len(entries) != q:
            raise InvalidSnapshot(
                f"expected one entry per action ({q})", field="transitions.actions"
            )
        for a, entry in enumerate(entries):
            field = f"transitions.actions.{a}"
            width = stored.integer(entry["width"], f"{field}.width", high=max(2 * n, 8))
            nnz = stored.ints(entry["nnz"], f"{field}.nnz", (n,), high=min(width, n))
            self._nnz[a] = nnz
            self._offset[a] = stored.floats(
                entry["offset"], f"{field}.offset", (n,), low=0.0, high=float(latest[a, 0])
            )
            self._row_sum[a] = stored.floats(entry["row_sum"], f"{field}.row_sum", (n,), low=0.0)
            total = int(nnz.sum())
            cols = stored.ints(
                entry["cols"], f"{field}.cols", (total,), high=max(n - 1, 0), dtype=np.int32
            )
            vals = stored.floats(entry["vals"], f"{field}.vals", (total,), low=0.0)
            rows = np.repeat(np.arange(n, dtype=np.int64), nnz)
            if np.unique(rows * max(n, 1) + cols).size != total:
                raise InvalidSnapshot("a row names a next state twice", field=f"{field}.cols")
            # each row's learned sum is its entries' (nnz 0: nothing learned, a sum of 0)
            if not np.allclose(
                np.bincount(rows, weights=vals, minlength=n), self._row_sum[a], rtol=1e-6, atol=0.0
            ):
                raise InvalidSnapshot(
                    "a row's learned sum is not the sum of its entries", field=f"{field}.row_sum"
                )
            self._cap[a] = nnz
            pool_cols.append(cols)
            pool_vals.append(vals)
        self._pool_cols = np.concatenate([np.zeros(0, dtype=np.int32), *pool_cols])
        self._pool_vals = np.concatenate([np.zeros(0), *pool_vals])
        self._used[0] = self._pool_vals.size
        self._start[:] = (np.cumsum(self._cap.ravel()) - self._cap.ravel()).reshape(q, n)
        self._refresh()
        return self


@njit(cache=True)
def _row_log_norm(log_pad: float, offset: float, row_sum: float) -> float:
    """``log(F_o / D_a)`` of a row: its padding mass (+) its learned mass. A row without
    learned mass (never learned, reset, or reached only by a belief state of negligible
    probability) has log 0 = -inf there, and its normaliser is the padding alone."""
    log_learned = math.log(row_sum) if row_sum > 0.0 else NEG_INF
    return logaddexp(log_pad, offset + log_learned)


@njit(cache=True)
def _row_scales(
    log_pad: float, log_level: float, offset: float, row_sum: float
) -> tuple[float, float]:
    """A row's learned and padding scales (see :meth:`LazyTransitions._refresh_scales`)."""
    log_norm = _row_log_norm(log_pad, offset, row_sum)
    return math.exp(offset - log_norm), math.exp(log_level - log_norm)


@njit(cache=True)
def _log_norm(log_pad: FloatArray, offset: FloatArray, row_sum: FloatArray) -> FloatArray:
    """:func:`_row_log_norm` of every row of a vector of rows."""
    out = np.empty(log_pad.shape[0])
    for i in range(log_pad.shape[0]):
        out[i] = _row_log_norm(log_pad[i], offset[i], row_sum[i])
    return out


@njit(cache=True)
def _scales(
    log_pad: FloatArray, log_level: FloatArray, offset: FloatArray, row_sum: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """:func:`_row_scales` of every row (actions x states): their learned and padding
    scales."""
    learned, pad = np.empty_like(log_pad), np.empty_like(log_pad)
    for a in range(log_pad.shape[0]):
        for i in range(log_pad.shape[1]):
            learned[a, i], pad[a, i] = _row_scales(
                log_pad[a, i], log_level[a, i], offset[a, i], row_sum[a, i]
            )
    return learned, pad


def _suffix_sums(x: FloatArray) -> FloatArray:
    """``out[..., i] = sum_{m >= i} x[..., m]``, with a trailing 0: sums over rows at or
    after i (along the last axis)."""
    out = np.zeros((*x.shape[:-1], x.shape[-1] + 1))
    x[..., ::-1].cumsum(axis=-1, out=out[..., -2::-1])
    return out


@njit(cache=True)
def learn(
    tpm: Any,
    a: int,
    rows: IntArray,
    tau: FloatArray,
    cols: IntArray,
    gamma: FloatArray,
) -> int:
    """:meth:`LazyTransitions.learn_one` on action ``a``'s rows, ``tpm`` the matrices'
    arrays (:meth:`LazyTransitions.arrays`; ``numbers`` and ``counts`` the per-row arrays).
    Returns 0, or, changing nothing, the slots it needs at the pool's end when the rows that
    must move there (to twice their room) do not fit.

    ``slots`` is a zeroed scratch map column -> slot + 1, filled for one row at a time and
    cleared again, so that finding the entries costs O(k W) whatever n is.
    """
    lr, log_decay, numbers, counts, pool_cols, pool_vals, used, slots = tpm
    offset, row_sum, log_pad, log_level, learned_scale, pad_scale = (
        numbers[0],
        numbers[1],
        numbers[2],
        numbers[3],
        numbers[4],
        numbers[5],
    )
    nnz, start, cap = counts[0], counts[1], counts[2]
    extra = 0
    for i in range(rows.shape[0]):  # first, without changing anything: is there room?
        row = rows[i]
        if nnz[a, row] + cols.shape[0] > cap[a, row]:
            needed = _row_needs(nnz[a, row], start[a, row], cols, pool_cols, slots)
            if needed > cap[a, row]:
                extra += max(needed, 2 * cap[a, row], 4)
    top = used[0]
    if top + extra > pool_vals.shape[0]:
        return extra
    if extra:
        for i in range(rows.shape[0]):  # rows without room move to the end, in order
            row = rows[i]
            if nnz[a, row] + cols.shape[0] > cap[a, row]:
                needed = _row_needs(nnz[a, row], start[a, row], cols, pool_cols, slots)
                if needed > cap[a, row]:
                    room = max(needed, 2 * cap[a, row], 4)
                    for s in range(nnz[a, row]):
                        pool_cols[top + s] = pool_cols[start[a, row] + s]
                        pool_vals[top + s] = pool_vals[start[a, row] + s]
                    start[a, row], cap[a, row] = top, room
                    top += room
        used[0] = top
    step = log_decay[a] + math.log1p(-lr)
    log_decay[a] = step
    base = -step  # the touched rows' new offset
    gamma_sum = pairwise_sum(gamma, gamma.shape[0])
    for i in range(rows.shape[0]):
        row = rows[i]
        factor = math.exp(offset[a, row] + step)  # <= 1
        offset[a, row] = base
        learned = row_sum[a, row] * factor + lr * tau[i] * gamma_sum
        row_sum[a, row] = learned
        learned_scale[a, row], pad_scale[a, row] = _row_scales(
            log_pad[a, row], log_level[a, row], base, learned
        )
        first, count = start[a, row], nnz[a, row]
        for s in range(first, first + count):
            pool_vals[s] *= factor
            slots[pool_cols[s]] = s - first + 1
        for j in range(cols.shape[0]):
            contrib = lr * tau[i] * gamma[j]
            slot = slots[cols[j]] - 1
            if slot >= 0:
                pool_vals[first + slot] += contrib
            else:
                pool_cols[first + count] = cols[j]
                pool_vals[first + count] = contrib
                count += 1
        for s in range(first, first + nnz[a, row]):
            slots[pool_cols[s]] = 0
        nnz[a, row] = count
    return 0


@njit(cache=True)
def _row_needs(count: int, first: int, cols: IntArray, pool_cols: ColArray, slots: IntArray) -> int:
    """How many entries a row of ``count`` entries from ``first`` holds once ``cols`` are in
    it (``slots`` zeroed before and after, as in :func:`_learn`)."""
    for s in range(first, first + count):
        slots[pool_cols[s]] = 1
    needed: int = count
    for j in range(cols.shape[0]):
        if slots[cols[j]] == 0:
            needed += 1
    for s in range(first, first + count):
        slots[pool_cols[s]] = 0
    return needed


@njit(cache=True)
def _compact(
    start: IntArray,
    cap: IntArray,
    nnz: IntArray,
    pool_cols: ColArray,
    pool_vals: FloatArray,
    new_cols: ColArray,
    new_vals: FloatArray,
) -> int:
    """Copy every row (actions x states) into the new pool, in order, each keeping its room;
    ``start`` is updated. Returns the slots in use."""
    used = 0
    for a in range(start.shape[0]):
        for row in range(start.shape[1]):
            first = start[a, row]
            for s in range(nnz[a, row]):
                new_cols[used + s] = pool_cols[first + s]
                new_vals[used + s] = pool_vals[first + s]
            start[a, row] = used
            used += cap[a, row]
    return used


@njit(cache=True)
def _add_learned(
    rows: IntArray,
    weights: FloatArray,
    start: IntArray,
    nnz: IntArray,
    pool_cols: ColArray,
    pool_vals: FloatArray,
    out: FloatArray,
) -> None:
    """``out[j] += weight_i * vals(i, j)`` over the rows, in row and slot order (the order of
    a weighted bincount of the rows' entries laid side by side)."""
    for i in range(rows.shape[0]):
        row, weight = rows[i], weights[i]
        for s in range(start[row], start[row] + nnz[row]):
            out[pool_cols[s]] += pool_vals[s] * weight


@njit(cache=True)
def _dot_rows(
    p: FloatArray,
    start: IntArray,
    nnz: IntArray,
    pool_cols: ColArray,
    pool_vals: FloatArray,
    out: FloatArray,
) -> None:
    """``out[i] = sum_s vals(i, s) p[cols(i, s)]`` for every row, summed in numpy's order."""
    widest = 0
    for i in range(out.shape[0]):
        widest = max(widest, nnz[i])
    terms = np.empty(widest)
    for i in range(out.shape[0]):
        count = nnz[i]
        for s in range(count):
            terms[s] = pool_vals[start[i] + s] * p[pool_cols[start[i] + s]]
        out[i] = pairwise_sum(terms, count)
