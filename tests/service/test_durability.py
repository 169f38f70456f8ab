"""Nothing acknowledged is lost after any single damaged file, with real servers killed
(SIGKILL) at random moments before and after each recovery, and no step sent again with its
idempotency key is applied twice (issue #69): one trial of ``bench/durability.py``."""

from __future__ import annotations

import pytest

from bench.durability import DAMAGE, trial

REPAIRED = {
    "torn journal (last 40 bytes cut)",
    "bit-flipped journal (last record)",
    "garbage journal tail (64 bytes)",
}

pytestmark = pytest.mark.slow  # real servers killed and restarted


def test_every_damaged_file_is_repaired_without_loss_or_set_aside() -> None:
    outcomes = trial(seed=69)
    assert set(outcomes) == set(DAMAGE)
    for kind, outcome in outcomes.items():
        assert outcome.recovery == ("repaired" if kind in REPAIRED else "quarantined"), kind
        assert outcome.lost == 0 and outcome.twice == 0, (kind, outcome)
        assert outcome.cut <= 1, (kind, outcome)  # at most the damaged last record
    assert all(outcomes[kind].acknowledged > 0 for kind in REPAIRED)
