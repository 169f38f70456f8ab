"""Invariants of an e-FSM, one function each, reusable on any model (river's check suite idea)."""

from __future__ import annotations

import numpy as np

from app.core import Shield
from app.core.revisers import RiskReviser


def risk_parts(shield: Shield) -> RiskReviser:
    """The shield's risk reviser, whose local model, record and trial a test reads."""
    assert isinstance(shield.reviser, RiskReviser)
    return shield.reviser


def check_tpm_rows_are_distributions(shield: Shield) -> None:
    """Every TPM is n x n and every row lies in [0, 1] and sums to 1."""
    n = shield.n_states
    for a in range(shield.config.action.n_bins):
        P = shield.transitions.matrix(a)
        assert P.shape == (n, n)
        assert np.all(P >= 0.0) and np.all(P <= 1.0 + 1e-12)
        np.testing.assert_allclose(P.sum(axis=1), 1.0, atol=1e-9)


def check_sizes_agree(shield: Shield) -> None:
    """States, matrices and flags agree on the number of states."""
    n = shield.n_states
    assert shield.transitions.n_states == n
    assert shield.flags.flags.shape == (n,)


def check_streams_hold_distributions(shield: Shield) -> None:
    """Every stream's remembered belief is a distribution over existing states."""
    for state in shield.streams.values():
        if state.belief is not None:
            assert np.all(state.belief.index < shield.n_states)
            assert state.belief.prob.sum() == np.float64(1.0) or np.isclose(
                state.belief.prob.sum(), 1.0
            )


def check_all(shield: Shield) -> None:
    """Every invariant above."""
    check_sizes_agree(shield)
    check_tpm_rows_are_distributions(shield)
    check_streams_hold_distributions(shield)
