"""Behaviour: in a world where some actions always fail, the shield learns to replace them."""

from __future__ import annotations

import numpy as np

from app.core import Shield
from tests.utils import cliff_config, run_cliff


def test_the_reviser_replaces_failing_actions_and_lets_safe_ones_pass() -> None:
    episodes = 120
    unshielded, _ = run_cliff(None, episodes, seed=11)
    shield = Shield(cliff_config(activate_after_episodes=10))
    shielded, pairs = run_cliff(shield, episodes, seed=11)

    late = slice(40, None)  # after activation and a few flagged visits
    assert np.mean(unshielded[late]) > 0.8  # a random controller nearly always falls
    assert np.mean(shielded[late]) < 0.1
    assert shield.counters.interventions["collision"] > 0

    late_pairs = pairs[len(pairs) // 2 :]
    risky = [(p, a) for p, a in late_pairs if p >= 1.0]
    safe = [(p, a) for p, a in late_pairs if p <= 0.6]
    assert risky and safe
    assert all(a < 1.0 for _, a in risky[5:])  # failing actions are replaced ...
    assert all(a == p for p, a in safe)  # ... and safe ones pass unchanged
