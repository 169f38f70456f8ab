"""Lead-vehicle speed profiles at the simulator's 0.25 s step, and 200 s windows of them.

Three sources: real driving (the committed CMAP traces, split by vehicle into training and
evaluation), the eight EPA schedules (evaluation and stress), and a seeded synthetic generator
(stop, accelerate, cruise, brake; for tests and for hard braking on purpose). Every profile is
clipped to [0, 32] m/s and passed through a forward rate limiter of +-2 m/s^2.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Literal

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]

DT = 0.25  # [s] simulator step
WINDOW_STEPS = 800  # a 200 s episode
V_MAX = 32.0  # [m/s]
A_MAX = 2.0  # [m/s^2]
MPH = 0.44704  # [m/s per mph]
DATA = Path(__file__).resolve().parents[1] / "data"


def resample(speed_1hz: FloatArray) -> FloatArray:
    """From 1 Hz to the 0.25 s step by linear interpolation."""
    t = np.arange(len(speed_1hz), dtype=np.float64)
    return np.interp(np.arange(0.0, t[-1] + 1e-9, DT), t, speed_1hz)


def rate_limit(speed: FloatArray, a_max: float = A_MAX, dt: float = DT) -> FloatArray:
    """Forward rate limiter: ``v[t] = v[t-1] + clip(x[t] - v[t-1], -a dt, a dt)``, in [0, 32]."""
    out = np.empty_like(speed)
    step = a_max * dt
    previous = float(np.clip(speed[0], 0.0, V_MAX))
    for i, target in enumerate(np.clip(speed, 0.0, V_MAX).tolist()):
        previous += min(max(target - previous, -step), step)
        out[i] = previous
    return out


@dataclass(frozen=True)
class LeadProfiles:
    """Named speed traces at 0.25 s, each at least one window long."""

    traces: tuple[FloatArray, ...]
    names: tuple[str, ...]

    def window(self, rng: np.random.Generator) -> FloatArray:
        """A random 200 s window (801 samples): a trace weighted by its windows, then a start."""
        starts = np.array([len(t) - WINDOW_STEPS for t in self.traces], dtype=np.float64)
        index = int(rng.choice(len(self.traces), p=starts / starts.sum()))
        start = int(rng.integers(0, len(self.traces[index]) - WINDOW_STEPS))
        return self.traces[index][start : start + WINDOW_STEPS + 1].copy()

    def __len__(self) -> int:
        return len(self.traces)

    @property
    def hours(self) -> float:
        """Total duration."""
        return sum(len(t) - 1 for t in self.traces) * DT / 3600


@lru_cache(maxsize=4)
def cmap(split: Literal["train", "evaluation", "all"] = "train") -> LeadProfiles:
    """The real-driving traces of ``client/data/lead_profiles.npz``."""
    with np.load(DATA / "lead_profiles.npz") as data:
        speed = data["speed"].astype(np.float64)
        ends = np.append(data["trip_start"][1:], len(speed))
        held = data["evaluation"][data["trip_vehicle"]]
        vehicles = data["vehicle"][data["trip_vehicle"]]
        trips = [
            (f"{vehicles[i]}#{i}", rate_limit(resample(speed[s:e])))
            for i, (s, e) in enumerate(zip(data["trip_start"], ends, strict=True))
            if split == "all" or held[i] == (split == "evaluation")
        ]
    return LeadProfiles(tuple(t for _, t in trips), tuple(n for n, _ in trips))


@lru_cache(maxsize=1)
def epa() -> LeadProfiles:
    """The eight EPA schedules; US06, REP05 and LA92 are changed by the rate limiter."""
    names, traces = [], []
    for path in sorted((DATA / "drive_cycles").glob("epa_*.csv")):
        with open(path) as f:
            mph = np.array([float(row["speed_mph"]) for row in csv.DictReader(f)])
        names.append(path.stem.removeprefix("epa_"))
        traces.append(rate_limit(resample(mph * MPH)))
    return LeadProfiles(tuple(traces), tuple(names))


def synthetic(
    seed: int, count: int = 8, duration_s: float = 600.0, hard_braking: bool = False
) -> LeadProfiles:
    """Seeded traces of stop / accelerate / cruise / brake regimes with bounded jerk.

    ``hard_braking`` makes every braking regime brake at the full 2 m/s^2.
    """
    rng = np.random.default_rng(seed)
    jerk = 1.0 * DT  # [m/s^3 * s] largest change of acceleration per step
    traces = []
    for _ in range(count):
        n = int(duration_s / DT) + 1
        v, a = float(rng.uniform(0.0, 25.0)), 0.0
        speed = np.empty(n)
        remaining, target = 0, 0.0
        for i in range(n):
            if remaining == 0:
                regime = rng.choice(["stop", "accelerate", "cruise", "brake"])
                remaining = int(rng.uniform(5.0, 30.0) / DT)
                target = {
                    "stop": -v / max(remaining * DT, 1.0),
                    "accelerate": rng.uniform(0.3, A_MAX),
                    "cruise": 0.0,
                    "brake": -A_MAX if hard_braking else -rng.uniform(0.3, A_MAX),
                }[regime]
            a += float(np.clip(target - a, -jerk, jerk))
            v = float(np.clip(v + a * DT, 0.0, V_MAX))
            speed[i] = v
            remaining -= 1
        traces.append(rate_limit(speed))
    return LeadProfiles(tuple(traces), tuple(f"synthetic-{seed}-{i}" for i in range(count)))
