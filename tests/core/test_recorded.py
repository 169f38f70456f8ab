"""The core decides as it did when the recordings were made (:mod:`tests.core.recorded`):
every applied action, recognised state and state count of 12,000 closed-loop steps; and a
snapshot that an earlier core wrote goes on as the live model does."""

from __future__ import annotations

import gzip
import json

import numpy as np
import pytest

from app.core import Shield
from app.core.trial import NONE
from app.service import codec
from tests.core.recorded import DATA, PRESETS, drive, path, preset
from tests.utils import assert_same


@pytest.mark.slow  # 12,000 steps a preset
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


def test_a_format_3_snapshot_of_the_local_model_restores_what_it_holds_and_goes_on() -> None:
    """``snapshot-format-3.json.gz``: the closing snapshot of the recorded loop's first 3,000
    steps of the default preset, written by the core at commit acb0707 (snapshot format 3 with
    the counted model's counts, log and table; configuration version 2 with its settings), a
    stream in the middle of an episode. It restores under the configuration it was written
    with (before the reach: without it) to a model that holds every array it held but the
    counted model's, bit for bit, and goes on as a model restored from its own snapshot does.
    (Until the risk reviser applied an end bin at the range's end, the same 3,000 steps of
    today's core made this model exactly.)"""
    with gzip.open(DATA / "snapshot-format-3.json.gz", "rt") as file:
        old = codec.from_json(json.load(file))
    assert old["format"] == 3 and "outcome_log" in old and old["config"]["version"] == 2
    restored = Shield.from_snapshot(old)
    assert restored.config == Shield(preset("no-reach")).config
    now = restored.snapshot()
    for key in ("clustering", "flags", "transitions"):
        assert_same(now[key], old[key], key)
    assert now["rng"] is None  # (the paper's reviser's noise: the risk reviser draws none)
    # its streams, each outside the trial (app.core.trial), which came after it
    for name, stream in now["streams"].items():
        assert (stream.pop("arm"), stream.pop("failed")) == (NONE, False)
        assert_same(stream, old["streams"][name], f"streams.{name}")
    # its counters, and the failures by kind (counted since) as its states counted them
    failures = now["counters"]["failures"]
    assert_same(
        {k: v for k, v in now["counters"].items() if k != "failures"}, old["counters"], "counters"
    )
    assert failures == dict(
        zip(
            ("collision", "large_distance"),
            old["flags"]["failures"].sum(axis=0).tolist(),
            strict=True,
        )
    )
    assert failures["collision"] > 0 and now["history"]["rows"].shape[0] == 1
    for key, value in old["local_risk"].items():
        assert_same(now["local_risk"][key], value, f"local_risk.{key}")
    twin = Shield.from_snapshot(now)
    rng = np.random.default_rng(1)
    for t in range(300):
        observation = [float(v) for v in rng.uniform([0, 0, 0], [30, 150, 30])]
        action = float(rng.uniform(-2, 2))
        done = t % 50 == 49
        event = "collision" if t % 100 == 99 else None
        first = twin.step(observation, None if done else action, done=done, event=event)
        second = restored.step(observation, None if done else action, done=done, event=event)
        assert first.to_dict() == second.to_dict()
    assert_same(restored.snapshot(), twin.snapshot())
