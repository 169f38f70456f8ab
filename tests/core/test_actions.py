from __future__ import annotations

import pytest

from app.core.actions import decode, encode
from app.core.config import ActionSpec

SPEC = ActionSpec()


def test_paper_discretisation_has_twenty_bins() -> None:
    assert SPEC.n_bins == 20


@pytest.mark.parametrize(
    ("action", "bin_index"),
    [(-2.0, 0), (-1.81, 0), (-1.8, 1), (0.0, 10), (0.2, 11), (0.39, 11), (1.99, 19), (2.0, 19)],
)
def test_encode_uses_half_open_intervals(action: float, bin_index: int) -> None:
    assert encode(action, SPEC) == bin_index


def test_encode_clips_out_of_range_actions() -> None:
    assert encode(-7.0, SPEC) == 0
    assert encode(9.0, SPEC) == 19


def test_decode_returns_the_interval_midpoint() -> None:
    # spec §6: [0.2, 0.4) -> 0.3
    assert decode(11, SPEC) == pytest.approx(0.3)
    assert decode(0, SPEC) == pytest.approx(-1.9)
    assert decode(-1, SPEC) == pytest.approx(-2.1)  # only the literal Alg. 2 goes there
    assert all(encode(decode(r, SPEC), SPEC) == r for r in range(SPEC.n_bins))
