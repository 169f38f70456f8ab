"""Held-out world for #68, third set (an unstable system whose saving direction depends on the
state): a car reversing a boat trailer down a narrow, winding lane to a slipway.

A car backs a single-axle boat trailer down a long lane to the slipway at a walking pace
(0.8-1.5 m/s, drawn per episode), between kerbs 1.0 m either side of the path the trailer's
axle should follow. The lane bends (two waves of bends, drawn per episode). Reversing, the
trailer is unstable: the hitch angle between car and trailer grows by itself, faster the
larger it is, and beyond about 40 degrees not even full lock brings it back. The action is the
steering angle asked of the car's front wheels, in [-0.55, 0.55] rad (positive turns them to
the left, as seen from the driver's seat), which the power steering follows within 0.3 s. To
move the trailer away from one kerb, the driver must first swing the hitch angle the other
way, towards a jackknife on that side; to straighten the hitch, they steer the trailer towards
a kerb. So the steering that saves the trailer from one failure carries it towards another,
and which is nearer depends on the state. Failures: ``jackknife_left`` (the trailer swung
more than 0.7 rad to the car's left; fought by steering left, a higher action) and
``jackknife_right`` (to the right; lower); ``kerb_left`` (the trailer's axle more than 1 m left
of its path; higher) and ``kerb_right`` (more than 1 m right of it; lower). Left alone with
the wheels straight, a trailer 0.1 rad off straight jackknifes or reaches the kerb on the side
it swung to within 3-9 s (5th-95th percentile). The ground is
rough: the trailer's wheels are knocked sideways by ruts and stones (a yaw disturbance of the
trailer, 0.03 rad/s standard deviation, correlated over 1 s).

The kinematic model of a car and an off-axle hitched trailer (C. Altafini 2003, after
P. Bolzern et al. 1998), with the car's rear axle moving at speed v (negative, reversing):
car heading theta1' = (v / L1) tan delta; trailer heading theta2' = (v / L2) (sin phi - (M /
L1) cos phi tan delta), hitch angle phi = theta1 - theta2; the trailer's axle moves at v cos
phi + v (M / L1) sin phi tan delta along theta2. Wheelbase L1 2.8 m, hitch M 1.0 m behind the
car's rear axle, the trailer's drawbar L2 (hitch to axle) drawn per episode in 2.2-4.0 m.

The controller is a trailer-assist system of the usual cascade: it asks the trailer a heading
that follows the path's own and turns back towards it in proportion to the trailer's offset;
asks the hitch the angle that turns the trailer towards that heading, within +-0.45 rad; and
steers the car to move the hitch towards that angle, through the inverse of the model. It
assumes a drawbar of 3 m, its camera reads the hitch angle and the trailer's offset 0-0.4 s
late (drawn per episode), the hitch angle with an offset (+-0.04 rad) from a misplaced
marker, and its three gains are drawn per episode: a system now well tuned for this trailer,
now too keen on the offset, now too slow on the hitch. Time step 0.2 s; an episode runs for
at most 250 steps (50 s, 40-75 m), ending at the first failure. The shield observes ``[hitch
angle, trailer offset, trailer heading error, steering angle]`` in rad, m, rad and rad: the
hitch angle (positive, the trailer swung to the car's left), the axle's offset from its path
(positive, left), the trailer's heading less the path's, and the front wheels' angle. The
controller's task figure (``info["task"]``, per step) is the absolute offset of the trailer's
axle from its path, in m. Held out: not used to choose any default (bench/heldout3/README.md).
"""

from __future__ import annotations

import math
from collections import deque
from typing import Any

import numpy as np
from gymnasium.spaces import Box

from app.core import Bound, ShieldConfig
from bench.worlds.harness import Spaces, plain_world
from client.shield.spaces import config_for

DT = 0.2  # [s]
SUBSTEPS = 4  # Euler steps of the motion per step
MAX_STEPS = 250  # 50 s
WHEELBASE = 2.8  # [m] L1, the car's
HITCH = 1.0  # [m] M, the hitch ball behind the car's rear axle
DRAWBAR = (2.2, 4.0)  # [m] L2, the hitch to the trailer's axle, per episode
DRAWBAR_ASSUMED = 3.0  # [m] the assist's
SPEED = (0.8, 1.5)  # [m/s] the reversing speed, per episode
STEER_MAX = 0.55  # [rad] full lock of the front wheels
STEER_LAG = 0.3  # [s] the power steering
JACKKNIFE = 0.7  # [rad] the hitch angle at which the trailer jackknifes
KERB = 1.0  # [m] the kerbs' distance from the trailer's path
BEND_SLOPE = 0.25  # the steepest slope of each of the two waves of bends
BEND_LENGTH = (25.0, 70.0)  # [m] their wavelengths
KNOCK = 0.03  # [rad/s] the trailer's yaw disturbance, standard deviation
KNOCK_TIME = 1.0  # [s] its correlation time
DELAY = (1, 4)  # [steps] the camera's reading is this many steps old less one, per episode
MARKER = 0.04  # [rad] the largest offset of the hitch-angle reading, per episode
HITCH_ASKED_MAX = 0.45  # [rad] the assist's limit on the hitch angle it asks
K_OFFSET = (0.25, 0.9)  # [rad/m] the trailer heading asked per m of offset, per episode
K_HEADING = (0.8, 2.5)  # the hitch angle asked per rad of heading error, per episode
K_HITCH = (0.8, 3.0)  # [1/m] the hitch's correction per rad of its gap, per episode


class Trailer:
    """The environment: reset/step like Gymnasium, with ``info["event"]`` and
    ``info["task"]``."""

    def __init__(self) -> None:
        self.rng = np.random.default_rng(0)
        self.x = self.y = self.heading = self.hitch = self.steer = self.knock = 0.0
        self.speed = self.drawbar = 0.0
        self.bends: list[tuple[float, float, float]] = []

    def reset(self, seed: int | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        self.rng = np.random.default_rng(seed)
        self.speed = float(self.rng.uniform(*SPEED))
        self.drawbar = float(self.rng.uniform(*DRAWBAR))
        self.bends = []  # amplitude [m], wavenumber [1/m], phase
        for _ in range(2):
            length = float(self.rng.uniform(*BEND_LENGTH))
            slope = float(self.rng.uniform(0.0, BEND_SLOPE))
            self.bends.append(
                (
                    slope * length / (2.0 * math.pi),
                    2.0 * math.pi / length,
                    float(self.rng.uniform(0.0, 2.0 * math.pi)),
                )
            )
        # the trailer's axle at x = 0 (it moves towards -x), near its path, nearly straight
        self.x = 0.0
        self.y = self.path(0.0) + float(self.rng.uniform(-0.3, 0.3))
        self.heading = math.atan(self.path_slope(0.0)) + float(self.rng.uniform(-0.05, 0.05))
        self.hitch = float(self.rng.uniform(-0.05, 0.05))
        self.steer = self.knock = 0.0
        return self._obs(), {"event": None, "task": abs(self.offset())}

    def path(self, x: float) -> float:
        """The lateral position of the trailer's path at ``x`` [m]."""
        return sum(a * math.sin(k * x + p) for a, k, p in self.bends)

    def path_slope(self, x: float) -> float:
        return sum(a * k * math.cos(k * x + p) for a, k, p in self.bends)

    def offset(self) -> float:
        """The trailer's axle left of its path [m] (left as seen from the car, facing +x)."""
        return (self.y - self.path(self.x)) * math.cos(math.atan(self.path_slope(self.x)))

    def heading_error(self) -> float:
        return self.heading - math.atan(self.path_slope(self.x))

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        asked = min(max(float(np.asarray(action).reshape(-1)[0]), -STEER_MAX), STEER_MAX)
        self.knock += -self.knock * DT / KNOCK_TIME + KNOCK * math.sqrt(
            2.0 * DT / KNOCK_TIME
        ) * float(self.rng.normal())
        v = -self.speed
        h = DT / SUBSTEPS
        for _ in range(SUBSTEPS):
            self.steer += (asked - self.steer) * h / STEER_LAG
            tan = math.tan(self.steer)
            car = v / WHEELBASE * tan
            trailer = (
                v
                / self.drawbar
                * (math.sin(self.hitch) - HITCH / WHEELBASE * math.cos(self.hitch) * tan)
                + self.knock
            )
            along = v * (math.cos(self.hitch) + HITCH / WHEELBASE * math.sin(self.hitch) * tan)
            self.x += along * math.cos(self.heading) * h
            self.y += along * math.sin(self.heading) * h
            self.heading += trailer * h
            self.hitch += (car - trailer) * h
        offset = self.offset()
        event = (
            "jackknife_left"
            if self.hitch > JACKKNIFE
            else "jackknife_right"
            if self.hitch < -JACKKNIFE
            else "kerb_left"
            if offset > KERB
            else "kerb_right"
            if offset < -KERB
            else None
        )
        return self._obs(), 0.0, event is not None, False, {"event": event, "task": abs(offset)}

    def _obs(self) -> np.ndarray:
        return np.array([self.hitch, self.offset(), self.heading_error(), self.steer])


class Assist:
    """A cascade on a late camera: the trailer's heading asked turns back towards the path in
    proportion to its offset; the hitch angle asked turns the trailer towards that heading;
    the steering moves the hitch towards that angle through the model's inverse, with an
    assumed drawbar. The latency, the marker's offset and the gains are drawn per episode."""

    def __init__(self, seed: int) -> None:
        self.rng = np.random.default_rng(seed)
        self.k_offset = self.k_heading = self.k_hitch = self.marker = 0.0
        self.seen: deque[tuple[float, float, float]] = deque()
        self.delay = 1

    def reset(self) -> None:
        self.k_offset = float(self.rng.uniform(*K_OFFSET))
        self.k_heading = float(self.rng.uniform(*K_HEADING))
        self.k_hitch = float(self.rng.uniform(*K_HITCH))
        self.marker = float(self.rng.uniform(-MARKER, MARKER))
        self.delay = int(self.rng.integers(*DELAY))
        self.seen = deque()

    def __call__(self, obs: np.ndarray) -> float:
        hitch, offset, heading, _ = (float(v) for v in obs)
        self.seen.append((hitch + self.marker, offset, heading))
        if len(self.seen) > self.delay:
            self.seen.popleft()
        hitch, offset, heading = self.seen[0]  # what the camera showed, late
        # reversing, an offset to the left is fought by a trailer heading turned up (+)
        heading_asked = math.atan(self.k_offset * offset)
        # the trailer's heading grows when the hitch angle is negative
        hitch_asked = -self.k_heading * (heading_asked - heading)
        hitch_asked = min(max(hitch_asked, -HITCH_ASKED_MAX), HITCH_ASKED_MAX)
        # reversing, hitch' = -(u / L1) tan delta (1 + (M / L2) cos phi) + (u / L2) sin phi;
        # ask hitch' = u k (asked - hitch)
        tan = (
            (math.sin(hitch) / DRAWBAR_ASSUMED - self.k_hitch * (hitch_asked - hitch))
            * WHEELBASE
            / (1.0 + HITCH / DRAWBAR_ASSUMED * math.cos(hitch))
        )
        return min(max(math.atan(tan), -STEER_MAX), STEER_MAX)


# What a new user writes (client.shield.config_for): the ranges the observation usually
# takes, the steering's range in 20 bins, and each failure with the direction of the steering
# that moves away from it; the second adds where each failure lies.
SPACES = Spaces(
    observation_space=Box(
        low=np.array([-JACKKNIFE, -KERB, -0.6, -STEER_MAX]),
        high=np.array([JACKKNIFE, KERB, 0.6, STEER_MAX]),
        dtype=np.float64,
    ),
    action_space=Box(low=-STEER_MAX, high=STEER_MAX, shape=(1,), dtype=np.float64),
)
CONFIG: ShieldConfig = config_for(
    SPACES,
    {
        "jackknife_left": "increase",
        "jackknife_right": "decrease",
        "kerb_left": "increase",
        "kerb_right": "decrease",
    },
)
BOUNDED: ShieldConfig = config_for(
    SPACES,
    {
        "jackknife_left": ("increase", Bound("x0", above=JACKKNIFE)),
        "jackknife_right": ("decrease", Bound("x0", below=-JACKKNIFE)),
        "kerb_left": ("increase", Bound("x1", above=KERB)),
        "kerb_right": ("decrease", Bound("x1", below=-KERB)),
    },
)


WORLD = plain_world("trailer", Trailer, Assist, CONFIG, MAX_STEPS)
WORLD_BOUNDED = plain_world("trailer-bounded", Trailer, Assist, BOUNDED, MAX_STEPS)
