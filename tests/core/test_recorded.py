"""The core decides as it did when the recordings were made (:mod:`tests.core.recorded`):
every applied action, recognised state and state count of 12,000 closed-loop steps; and a
snapshot that an earlier core wrote goes on as the live model does."""

from __future__ import annotations

import gzip
import json

import numpy as np
import pytest

from app.core import Shield
from app.service import codec
from tests.core.recorded import DATA, PRESETS, drive, path, preset, run
from tests.utils import assert_same


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


def test_a_format_3_snapshot_of_the_local_model_goes_on_as_the_live_model() -> None:
    """``snapshot-format-3.json.gz``: the closing snapshot of the recorded loop's first 3,000
    steps of the default preset, written by the core at commit acb0707 (snapshot format 3 with
    the counted model's counts, log and table; configuration version 2 with its settings), a
    stream in the middle of an episode. It restores to the model the same steps make now under
    its configuration (written before the reach: without it), and both decide alike after
    it."""
    with gzip.open(DATA / "snapshot-format-3.json.gz", "rt") as file:
        old = codec.from_json(json.load(file))
    assert old["format"] == 3 and "outcome_log" in old and old["config"]["version"] == 2
    restored = Shield.from_snapshot(old)
    live = Shield(preset("no-reach"))
    assert restored.config == live.config
    run(live, 3000)
    assert_same(restored.snapshot(), live.snapshot())
    rng = np.random.default_rng(1)
    for t in range(300):
        observation = [float(v) for v in rng.uniform([0, 0, 0], [30, 150, 30])]
        action = float(rng.uniform(-2, 2))
        done = t % 50 == 49
        event = "collision" if t % 100 == 99 else None
        first = live.step(observation, None if done else action, done=done, event=event)
        second = restored.step(observation, None if done else action, done=done, event=event)
        assert first.to_dict() == second.to_dict()
    assert_same(restored.snapshot(), live.snapshot())
