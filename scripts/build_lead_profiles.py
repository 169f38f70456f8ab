"""Build ``client/data/lead_profiles.npz`` from the CMAP real-driving traces in fastsim 2.1.2.

    python scripts/build_lead_profiles.py

The traces (NREL FASTSim's ``cmap_subset``: 1 Hz GPS speeds of 22 cars around Chicago, 2007,
Apache-2.0) ship inside the PyPI wheel ``fastsim==2.1.2``. The wheel is fetched with
``pip download`` under a pinned sha256 and read as a zip; fastsim is never installed. The
processing (spec experiment.md, "Lead-vehicle data"):

1. rebuild trips: a ``timestep`` above 1 s is a gap; a gap of 2-300 s with zero speed on both
   sides is a stop (filled with zeros), a gap of at most 5 s while moving is interpolated, any
   other gap splits the trip; trips shorter than 200 s are dropped;
2. mph to m/s, clipped to [0, 32];
3. a light centred smoothing (3-sample moving average) against GPS spikes;
4. stored at 1 Hz as float32; :mod:`client.sim.lead` interpolates to 0.25 s and applies the
   forward rate limiter of +-2 m/s^2 when it loads the file.

Vehicles are split into training and evaluation sets by vehicle, never by window. The licence
files of the wheel are copied next to the data, with a README that names the changes.
"""

from __future__ import annotations

import argparse
import hashlib
import io
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

import numpy as np

WHEEL = "fastsim==2.1.2"
SHA256 = "e03f42a1e2d7cd7f24b2d9205bd0a3a04b20a21a125491cf85581581b48e782e"
PREFIX = "fastsim/resources/cycles/cmap_subset/"
MPH = 0.44704  # [m/s per mph]
V_MAX = 32.0  # [m/s]
MIN_TRIP = 200  # [s]
STOP_GAP = (2, 300)  # [s] zero speed on both sides: a stop
MOVING_GAP = 5  # [s] interpolated while moving
OUT = Path(__file__).resolve().parents[1] / "client" / "data"


def fetch_wheel(directory: Path) -> Path:
    """Download the wheel (no install, no dependencies) and check its hash."""
    requirements = directory / "requirements.txt"
    requirements.write_text(f"{WHEEL} --hash=sha256:{SHA256}\n")
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "download",
            "--quiet",
            "--no-deps",
            "--only-binary=:all:",
            "--python-version",
            "3.10",
            "--platform",
            "manylinux2014_x86_64",
            "--require-hashes",
            "-r",
            str(requirements),
            "-d",
            str(directory),
        ],
        check=True,
    )
    [wheel] = directory.glob("fastsim-2.1.2-*.whl")
    if hashlib.sha256(wheel.read_bytes()).hexdigest() != SHA256:
        raise SystemExit(f"{wheel.name}: sha256 mismatch")
    return wheel


def rebuild_trips(timestep: np.ndarray, mph: np.ndarray) -> list[np.ndarray]:
    """Contiguous 1 Hz trips (mph) from one day file, by the gap rules of the module doc.

    ``timestep[i]`` is the time since sample i - 1 [s].
    """
    trips: list[np.ndarray] = []
    current = [float(mph[0])]
    for i in range(1, len(timestep)):
        gap = int(timestep[i])
        before, after = current[-1], float(mph[i])
        if gap == 1:
            pass
        elif STOP_GAP[0] <= gap <= STOP_GAP[1] and before == 0.0 and after == 0.0:
            current.extend([0.0] * (gap - 1))
        elif 2 <= gap <= MOVING_GAP:
            current.extend(np.linspace(before, after, gap + 1)[1:-1].tolist())
        else:
            trips.append(np.array(current))
            current = []
        current.append(after)
    trips.append(np.array(current))
    return [t for t in trips if len(t) - 1 >= MIN_TRIP]


def smooth(v: np.ndarray) -> np.ndarray:
    """Centred 3-sample moving average; the ends keep their values."""
    out = v.copy()
    out[1:-1] = (v[:-2] + v[1:-1] + v[2:]) / 3.0
    return out


def build(wheel: Path) -> dict[str, np.ndarray]:
    speeds, starts, vehicles_of_trip = [], [], []
    vehicles: list[str] = []
    offset = 0
    with zipfile.ZipFile(wheel) as archive:
        names = sorted(
            n
            for n in archive.namelist()
            if n.startswith(PREFIX) and n.endswith(".csv") and not n.endswith("trips.csv")
        )
        for name in names:
            vehicle = name[len(PREFIX) :].split("/")[0]
            if vehicle not in vehicles:
                vehicles.append(vehicle)
            table = np.genfromtxt(
                io.BytesIO(archive.read(name)),
                delimiter=",",
                names=True,
                usecols=("timestep", "speed_mph"),
            )
            for trip in rebuild_trips(table["timestep"], table["speed_mph"]):
                v = smooth(np.clip(trip * MPH, 0.0, V_MAX))
                speeds.append(v.astype(np.float32))
                starts.append(offset)
                vehicles_of_trip.append(vehicles.index(vehicle))
                offset += len(v)
        licence = archive.read("fastsim-2.1.2.dist-info/license_files/LICENSE")
        notice = archive.read("fastsim-2.1.2.dist-info/license_files/NOTICE")
    (OUT / "LICENSE").write_bytes(licence)
    (OUT / "NOTICE").write_bytes(notice)
    trip_vehicle = np.array(vehicles_of_trip)
    lengths = np.diff(np.append(starts, offset))
    hours = np.bincount(trip_vehicle, weights=lengths, minlength=len(vehicles)) / 3600
    return {
        "speed": np.concatenate(speeds),
        "trip_start": np.array(starts, dtype=np.int64),
        "trip_vehicle": trip_vehicle.astype(np.int64),
        "vehicle": np.array(vehicles),
        "evaluation": evaluation_vehicles(vehicles, hours),
    }


def evaluation_vehicles(vehicles: list[str], hours: np.ndarray) -> np.ndarray:
    """Every fourth vehicle by id is held out for evaluation."""
    order = np.argsort(vehicles)
    held = np.zeros(len(vehicles), dtype=bool)
    held[order[3::4]] = True
    return held


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--wheel", type=Path, help="use a wheel already downloaded")
    args = parser.parse_args()
    OUT.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        wheel = args.wheel or fetch_wheel(Path(tmp))
        data = build(wheel)
    np.savez_compressed(OUT / "lead_profiles.npz", **data)
    lengths = np.diff(np.append(data["trip_start"], len(data["speed"]))) - 1  # durations [s]
    held = data["evaluation"][data["trip_vehicle"]]
    print(
        f"{len(lengths)} trips, {lengths.sum() / 3600:.1f} h from {len(data['vehicle'])} "
        f"vehicles; evaluation: {held.sum()} trips, {lengths[held].sum() / 3600:.1f} h; "
        f"{(OUT / 'lead_profiles.npz').stat().st_size / 1e6:.2f} MB"
    )


if __name__ == "__main__":
    main()
