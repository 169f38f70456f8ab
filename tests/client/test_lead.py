"""The lead-vehicle data: the spec's invariants on the committed file, EPA and synthetic sets."""

from __future__ import annotations

import numpy as np
import pytest

from client.sim import lead


@pytest.mark.parametrize(
    "profiles",
    [lead.cmap("train"), lead.cmap("evaluation"), lead.epa(), lead.synthetic(3, hard_braking=True)],
    ids=["cmap-train", "cmap-evaluation", "epa", "synthetic"],
)
def test_windows_hold_the_invariants(profiles: lead.LeadProfiles) -> None:
    rng = np.random.default_rng(0)
    for _ in range(200):
        w = profiles.window(rng)
        assert w.shape == (801,)
        assert w.min() >= 0.0 and w.max() <= 32.0
        assert np.abs(np.diff(w)).max() / lead.DT <= 2.0 + 1e-9


def test_the_same_seed_gives_the_same_windows() -> None:
    profiles = lead.cmap("train")
    a = [profiles.window(np.random.default_rng(7)) for _ in range(3)]
    b = [profiles.window(np.random.default_rng(7)) for _ in range(3)]
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x, y)
    assert not np.array_equal(profiles.window(np.random.default_rng(8)), a[0])


def test_the_committed_file_is_real_driving_split_by_vehicle() -> None:
    train, held = lead.cmap("train"), lead.cmap("evaluation")
    assert len(train) + len(held) == 232
    assert train.hours + held.hours == pytest.approx(67.8, abs=0.05)
    vehicles = {name.split("#")[0] for name in train.names}
    assert not vehicles & {name.split("#")[0] for name in held.names}
    assert all(len(t) >= 801 for t in train.traces + held.traces)


def test_epa_stress_cycles_are_limited() -> None:
    cycles = lead.epa()
    assert cycles.names == ("hudds", "hwfet", "la92", "nycc", "rep05", "sc03", "udds", "us06")
    # US06 asks for more than 2 m/s^2; the limiter holds it to exactly that
    us06 = cycles.traces[cycles.names.index("us06")]
    assert np.abs(np.diff(us06)).max() / lead.DT == pytest.approx(2.0)


def test_rate_limiter_and_resampling() -> None:
    step = np.array([0.0, 10.0, 10.0, 10.0])
    limited = lead.rate_limit(lead.resample(step))
    assert len(limited) == 13  # 3 s at 0.25 s
    assert np.diff(limited).max() == pytest.approx(0.5)  # 2 m/s^2 * 0.25 s
    assert limited[-1] == pytest.approx(6.0)  # still catching up after 3 s


def test_synthetic_hard_braking_brakes_at_the_limit() -> None:
    profiles = lead.synthetic(0, hard_braking=True)
    assert min(np.diff(t).min() for t in profiles.traces) / lead.DT == pytest.approx(-2.0)
    np.testing.assert_array_equal(lead.synthetic(0).traces[0], lead.synthetic(0).traces[0])


def test_trip_rebuilding_follows_the_gap_rules() -> None:
    import importlib.util
    from pathlib import Path

    path = Path(__file__).parents[2] / "scripts" / "build_lead_profiles.py"
    spec = importlib.util.spec_from_file_location("build_lead_profiles", path)
    assert spec is not None and spec.loader is not None
    build = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(build)

    ones = [1.0] * 250
    # a 100 s stop (zero on both sides) is filled with zeros: one trip
    timestep = np.array([1, *ones[:99], 100, *ones[:150]])
    mph = np.array([10.0] * 99 + [0.0, 0.0] + [10.0] * 150)
    [trip] = build.rebuild_trips(timestep, mph)
    assert len(trip) == 251 + 99
    # a 4 s gap while moving is interpolated
    [trip] = build.rebuild_trips(
        np.array([1, *ones[:150], 4, *ones[:100]]), np.array([10.0] * 151 + [14.0] * 101)
    )
    assert trip[151:154].tolist() == [11.0, 12.0, 13.0]
    # a 30 s gap while moving splits the trip; the short piece is dropped
    trips = build.rebuild_trips(np.array([1, *ones[:239], 30, *ones[:50]]), np.array([10.0] * 291))
    assert [len(t) for t in trips] == [240]
