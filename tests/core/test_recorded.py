"""The core decides as it did when the recordings were made (:mod:`tests.core.recorded`):
every applied action, recognised state and state count of 12,000 closed-loop steps."""

from __future__ import annotations

import numpy as np
import pytest

from tests.core.recorded import PRESETS, drive, path, preset


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_a_long_closed_loop_sequence_decides_as_recorded(name: str) -> None:
    recorded = np.load(path(name))
    now = drive(preset(name))
    assert recorded["revised"].sum() > 1000  # the reviser was at work in the recording
    for key in ("state", "n_states", "revised", "reason", "verdict"):
        np.testing.assert_array_equal(now[key], recorded[key], err_msg=key)
    np.testing.assert_array_equal(now["applied"], recorded["applied"])
    if "local_theta" in recorded:  # (recordings from before the local model lack it)
        np.testing.assert_array_equal(now["local_theta"], recorded["local_theta"])
