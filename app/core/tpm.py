"""Online transition identification, Eqs. 3-4 (docs/algorithm.md): pure functions and a dense model.

One transition-probability matrix (TPM) ``P^a`` per discrete action, row-stochastic:
``P^a(i, j) = Prob(s_{t+1} = j | s_t = i, a_t = a)`` (Eq. 2). The pure functions are the maths
in its two exact forms:

* literal counts (Eqs. 3-4): ``F <- F + phi (tau gamma^T - F)``, ``F_o <- F_o + phi (tau - F_o)``,
  ``P = diag(F_o)^-1 F``; this form underflows after long runs;
* the stable form: keep ``P`` and ``F_o`` and update only the rows that ``tau`` touches.

:class:`DenseTransitions` stores every matrix densely in the stable form: the straightforward
implementation, exact and simple, used as the oracle in tests and the baseline in ``bench/``.
The default backend is :class:`app.core.lazy_tpm.LazyTransitions`, which gives the same numbers
without n x n storage.
"""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np
import numpy.typing as npt

from app.core import _stored as stored
from app.core.belief import Belief
from app.core.config import TransitionConfig
from app.core.errors import InvalidSnapshot

FloatArray = npt.NDArray[np.float64]


class TransitionModel(Protocol):
    """What the shield needs from a set of TPMs, one per action."""

    n_actions: int

    @property
    def n_states(self) -> int:
        """Current matrix size n."""
        ...

    def add_state(self) -> None:
        """Expand every matrix by one row and one column (docs/algorithm.md)."""
        ...

    def learn_one(self, prev: Belief, action_bin: int, belief: Belief) -> None:
        """Eqs. 3-4 for the matrix of ``action_bin`` with tau = prev, gamma = belief."""
        ...

    def predict(self, belief: Belief, action_bin: int, transpose: bool) -> FloatArray:
        """Eq. 5: ``P^T belief`` (transpose,) or the literal ``P belief`` (A1)."""
        ...

    def predict_marginal(self, belief: Belief, transpose: bool) -> FloatArray:
        """Eq. 7's step: Eq. 5 under the marginal TPM ``P* = (1/q) sum_r P^r``."""
        ...

    def reset_row(self, state: int) -> None:
        """Forget what was learned about leaving ``state`` (A16 ``reset``)."""
        ...

    def matrix(self, action_bin: int) -> FloatArray:
        """The dense n x n matrix of one action."""
        ...

    def snapshot(self) -> dict[str, Any]:
        """Exact state as plain data and arrays."""
        ...


def marginal_by_action(model: TransitionModel, belief: Belief, transpose: bool) -> FloatArray:
    """Eq. 7's step as written: the mean of Eq. 5 over every action, summed in action order."""
    q = model.n_actions
    total: FloatArray = (
        sum((model.predict(belief, r, transpose) for r in range(q)), np.zeros(model.n_states)) / q
    )
    return total


# --- Literal Eqs. 3-4 ----------------------------------------------------------------------


def update_counts(
    F: FloatArray, F_o: FloatArray, tau: FloatArray, gamma: FloatArray, lr: float
) -> tuple[FloatArray, FloatArray]:
    """Eqs. 3-4: ``F += phi (tau gamma^T - F)``, ``F_o += phi (tau gamma^T 1 - F_o)``."""
    F_new = F + lr * (np.outer(tau, gamma) - F)
    F_o_new = F_o + lr * (tau * gamma.sum() - F_o)
    return F_new, F_o_new


def grow_counts(F: FloatArray, F_o: FloatArray, prior: float) -> tuple[FloatArray, FloatArray]:
    """Expansion with epsilon-bar padding: a new row and column of epsilon-bar."""
    n = F.shape[0]
    F_new = np.full((n + 1, n + 1), prior)
    F_new[:n, :n] = F
    return F_new, np.append(F_o + prior, (n + 1) * prior)


def probabilities(F: FloatArray, F_o: FloatArray) -> FloatArray:
    """Eq. 4: ``P = diag(F_o)^-1 F``."""
    return F / F_o[:, None]


# --- Stable form ---------------------------------------------------------------------


def update_stable(
    P: FloatArray, F_o: FloatArray, tau: FloatArray, gamma: FloatArray, lr: float
) -> tuple[FloatArray, FloatArray]:
    """Eqs. 3-4 on (P, F_o): ``w_i = phi tau_i / ((1-phi) F_o,i + phi tau_i)``,
    ``P_i += w_i (gamma - P_i)``, ``F_o,i = (1-phi) F_o,i + phi tau_i``."""
    decayed = (1.0 - lr) * F_o
    gain = lr * tau
    touched = tau > 0
    w = np.zeros_like(tau)
    w[touched] = gain[touched] / (decayed[touched] + gain[touched])
    P_new = P + w[:, None] * (gamma[None, :] - P)
    return P_new, decayed + gain


def grow_stable(
    P: FloatArray, F_o: FloatArray, prior: float, mode: str
) -> tuple[FloatArray, FloatArray]:
    """Expansion (docs/algorithm.md) in the stable form.

    ``prior``: old row ``i`` becomes ``[F_o,i P_i, eps] / (F_o,i + eps)``, the new row is
    uniform. ``zero_uniform`` / ``zero_identity``: old rows gain a zero column, the new row is
    uniform or a self-loop.
    """
    n = P.shape[0]
    P_new = np.zeros((n + 1, n + 1))
    if mode == "prior":
        P_new[:n, :n] = F_o[:, None] * P
        P_new[:n, n] = prior
        P_new[:n] /= (F_o + prior)[:, None]
        F_o_old = F_o + prior
    else:
        P_new[:n, :n] = P
        F_o_old = F_o
    if mode == "zero_identity":
        P_new[n, n] = 1.0
        F_o_new = prior
    else:
        P_new[n] = 1.0 / (n + 1)
        F_o_new = (n + 1) * prior
    return P_new, np.append(F_o_old, F_o_new)


class DenseTransitions:
    """Every TPM as a dense array in the stable form: exact, O(q n^2) memory."""

    def __init__(self, n_actions: int, config: TransitionConfig) -> None:
        self.config = config
        self.n_actions = n_actions
        self.P = np.zeros((n_actions, 0, 0))
        self.F_o = np.zeros((n_actions, 0))

    @property
    def n_states(self) -> int:
        """Current matrix size n."""
        return int(self.P.shape[1])

    def add_state(self) -> None:
        """Expand every matrix."""
        grown = [
            grow_stable(P, F_o, self.config.prior, self.config.expansion)
            for P, F_o in zip(self.P, self.F_o, strict=True)
        ]
        self.P = np.stack([P for P, _ in grown])
        self.F_o = np.stack([F_o for _, F_o in grown])

    def learn_one(self, prev: Belief, action_bin: int, belief: Belief) -> None:
        """Eqs. 3-4 on the matrix of the applied action only."""
        n = self.n_states
        tau, gamma = prev.dense(n), belief.dense(n)
        P, F_o = update_stable(
            self.P[action_bin], self.F_o[action_bin], tau, gamma, self.config.learning_rate
        )
        self.P[action_bin], self.F_o[action_bin] = P, F_o

    def predict(self, belief: Belief, action_bin: int, transpose: bool) -> FloatArray:
        """Eq. 5 (A1), summed in a fixed order (rows in turn, or each row pairwise) rather than
        by BLAS, whose order follows the CPU (docs/algorithm.md, "Determinism")."""
        p = belief.dense(self.n_states)
        P = self.P[action_bin]
        if transpose:
            return np.add.reduce(p[:, None] * P, axis=0)  # type: ignore[no-any-return]
        pred: FloatArray = (P * p).sum(axis=1)
        return pred

    def predict_marginal(self, belief: Belief, transpose: bool) -> FloatArray:
        """Eq. 7's step."""
        return marginal_by_action(self, belief, transpose)

    def reset_row(self, state: int) -> None:
        """A16 ``reset`` is only offered by the lazy backend, which knows each pad's age."""
        raise NotImplementedError("on_replace='reset' needs the lazy TPM backend")

    def matrix(self, action_bin: int) -> FloatArray:
        """The dense matrix of one action."""
        matrix: FloatArray = self.P[action_bin].copy()
        return matrix

    def snapshot(self) -> dict[str, Any]:
        """Exact state."""
        return {"backend": "dense", "P": self.P.copy(), "F_o": self.F_o.copy()}

    @classmethod
    def restore(
        cls, n_actions: int, config: TransitionConfig, data: dict[str, Any]
    ) -> DenseTransitions:
        """Rebuild from :meth:`snapshot` output, every part checked."""
        self = cls(n_actions, config)
        P = stored.floats(data["P"], "transitions.P", low=0.0, high=1.0)
        n = P.shape[1] if P.ndim == 3 else -1
        if P.shape != (n_actions, n, n):
            raise InvalidSnapshot("expected one square matrix per action", field="transitions.P")
        if not np.allclose(P.sum(axis=2), 1.0, rtol=0.0, atol=stored.SUM_TOLERANCE):
            raise InvalidSnapshot("a row of a matrix does not sum to 1", field="transitions.P")
        self.P = P
        self.F_o = stored.floats(data["F_o"], "transitions.F_o", (n_actions, n), low=0.0)
        return self
