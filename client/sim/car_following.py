"""The paper's car-following world (section 3.1) as a Gymnasium environment."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal

import gymnasium as gym
import numpy as np
import numpy.typing as npt

from app.core import ShieldConfig
from client.sim import lead as lead_data

DT = lead_data.DT  # [s]
A_MAX = 2.0  # [m/s^2]
V_MAX = 32.0  # [m/s]
MAX_STEPS = lead_data.WINDOW_STEPS  # 800 steps = 200 s
LARGE_DISTANCE = 200.0  # [m]
ENV_ID = "CarFollowing-v0"


@dataclass(frozen=True)
class RewardConfig:
    """Constants of Eqs. 10-12, which the paper does not give.

    ``form="as_written"`` uses ``headway_const * d_safe`` as the target distance, as Eq. 11 is
    printed; ``"time_headway"`` uses ``d_safe + headway_const * v_ego`` (spec A15).
    """

    v_max: float = 32.0  # [m/s]
    headway_const: float = 2.0  # [s]
    d_safe: float = 10.0  # [m]
    accel_max: float = 2.0  # [m/s^2]
    form: Literal["as_written", "time_headway"] = "as_written"
    # subtracted from the reward of a step that ends in a failure; the paper gives none, and
    # with every term of Eqs. 10-12 <= 0 an episode ended early is then the best a learner
    # with terminal value 0 can reach
    failure_penalty: float = 0.0


@dataclass(frozen=True)
class StartConfig:
    """How episodes start: a headway below 100 m and an ego speed near the lead's."""

    headway: tuple[float, float] = (10.0, 100.0)  # [m]
    speed_offset: tuple[float, float] = (-5.0, 5.0)  # [m/s] ego minus lead


class CarFollowingEnv(gym.Env[npt.NDArray[np.float32], npt.NDArray[np.float32]]):
    """Follow a lead vehicle on one lane as fast and as safely as possible.

    ## Description
    Two point masses on one lane (Han et al., IFAC 2020, section 3.1). The lead vehicle replays
    a 200 s window of a speed profile; the agent sets the ego vehicle's acceleration.

    ## Observation (Eq. 9)
    | index | quantity | unit |
    |---|---|---|
    | 0 | ego speed v_ego | m/s |
    | 1 | headway (lead position minus ego position) | m |
    | 2 | lead speed v_lead | m/s |
    | 3 | the ego acceleration applied at the previous step | m/s^2 |

    ``info["efsm_observation"]`` is the e-FSM observation of Eq. 12, ``[v_ego, headway,
    v_lead]``; ``info["event"]`` is ``"collision"``, ``"large_distance"`` or None.

    ## Action
    The ego acceleration in [-2, 2] m/s^2 (clipped).

    ## Transition dynamics (Eq. 8), dt = 0.25 s
    ``x <- x + v dt`` then ``v <- clip(v + a dt, 0, 32)`` for both vehicles; the lead's speed
    follows its profile.

    ## Reward (Eqs. 10-12)
    ``exp(-(v_ego - v_lead)^2 / v_max) - 1 + exp(-(headway - target)^2 / (2 target)) - 1 +
    exp(-(a_t - a_{t-1})^2 / (2 accel_max)) - 1`` with ``target = headway_const * d_safe``
    (see :class:`RewardConfig`).

    ## Starting state
    A random lead window; headway uniform in [10, 100] m; ego speed the lead's plus a uniform
    offset in [-5, 5] m/s, clipped to [0, 32].

    ## Episode end
    Terminated on a collision (headway <= 0) or a large distance (headway > 200 m); truncated
    after 800 steps (a success).

    ## Arguments
    >>> env = CarFollowingEnv(lead=lead_data.synthetic(0))
    >>> obs, info = env.reset(seed=0)
    >>> obs.shape, info["event"]
    ((4,), None)

    ## Version history
    v0: the paper's setting with the constants of :class:`RewardConfig`.
    """

    metadata: dict[str, Any] = {"render_modes": []}

    def __init__(
        self,
        lead: lead_data.LeadProfiles | None = None,
        reward: RewardConfig | None = None,
        start: StartConfig | None = None,
    ) -> None:
        self.lead = lead if lead is not None else lead_data.cmap("train")
        self.reward_config = reward or RewardConfig()
        self.start = start or StartConfig()
        self.observation_space = gym.spaces.Box(
            low=np.array([0.0, -10.0, 0.0, -A_MAX], dtype=np.float32),
            high=np.array([V_MAX, LARGE_DISTANCE + 10.0, V_MAX, A_MAX], dtype=np.float32),
        )
        self.action_space = gym.spaces.Box(-A_MAX, A_MAX, shape=(1,), dtype=np.float32)
        self._profile = np.zeros(MAX_STEPS + 1)
        self._t = 0
        self._headway = self._v_ego = self._v_lead = self._a_prev = 0.0

    def shield_config(self) -> ShieldConfig:
        """The shield this world was made for: the e-FSM observation of ``info`` and the
        paper's failures (:func:`client.shield.spaces.config_for` reads it)."""
        return ShieldConfig()

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[npt.NDArray[np.float32], dict[str, Any]]:
        super().reset(seed=seed)
        rng = self.np_random
        self._profile = self.lead.window(rng)
        self._t = 0
        self._v_lead = float(self._profile[0])
        self._headway = float(rng.uniform(*self.start.headway))
        offset = float(rng.uniform(*self.start.speed_offset))
        self._v_ego = min(max(self._v_lead + offset, 0.0), V_MAX)
        self._a_prev = 0.0
        return self._observation(), self._info(None)

    def step(
        self, action: npt.NDArray[np.float32] | float
    ) -> tuple[npt.NDArray[np.float32], float, bool, bool, dict[str, Any]]:
        a = min(max(float(np.asarray(action).reshape(-1)[0]), -A_MAX), A_MAX)
        # Eq. 8: positions with the current speeds, then the speeds
        self._headway += (self._v_lead - self._v_ego) * DT
        self._v_ego = min(max(self._v_ego + a * DT, 0.0), V_MAX)
        self._t += 1
        self._v_lead = float(self._profile[self._t])
        reward = self._reward(a)
        self._a_prev = a
        event = None
        if self._headway <= 0.0:
            event = "collision"
        elif self._headway > LARGE_DISTANCE:
            event = "large_distance"
        terminated = event is not None
        if terminated:
            reward -= self.reward_config.failure_penalty
        truncated = not terminated and self._t >= MAX_STEPS
        return self._observation(), reward, terminated, truncated, self._info(event)

    def state(self) -> dict[str, Any]:
        """Where the episode stands and where the generator is: :meth:`restore` continues
        the episode (and the episodes after it) exactly."""
        return {
            "profile": self._profile.copy(),
            "t": self._t,
            "headway": self._headway,
            "v_ego": self._v_ego,
            "v_lead": self._v_lead,
            "a_prev": self._a_prev,
            "rng": self.np_random.bit_generator.state,
        }

    def restore(self, state: dict[str, Any]) -> None:
        self._profile = np.array(state["profile"])
        self._t, self._headway = state["t"], state["headway"]
        self._v_ego, self._v_lead, self._a_prev = state["v_ego"], state["v_lead"], state["a_prev"]
        self.np_random.bit_generator.state = state["rng"]

    def _reward(self, a: float) -> float:
        cfg = self.reward_config
        target = (
            cfg.headway_const * cfg.d_safe
            if cfg.form == "as_written"
            else cfg.d_safe + cfg.headway_const * self._v_ego
        )
        vel = math.exp(-((self._v_ego - self._v_lead) ** 2) / cfg.v_max) - 1.0  # Eq. 10
        dist = math.exp(-((self._headway - target) ** 2) / (2.0 * target)) - 1.0  # Eq. 11
        accel = math.exp(-((a - self._a_prev) ** 2) / (2.0 * cfg.accel_max)) - 1.0  # Eq. 12
        return vel + dist + accel

    def _observation(self) -> npt.NDArray[np.float32]:
        return np.array([self._v_ego, self._headway, self._v_lead, self._a_prev], dtype=np.float32)

    def _info(self, event: str | None) -> dict[str, Any]:
        return {
            "efsm_observation": [self._v_ego, self._headway, self._v_lead],
            "event": event,
            "speed_difference": abs(self._v_ego - self._v_lead),
            "step": self._t,
        }


def register() -> None:
    """Register ``CarFollowing-v0`` with Gymnasium (idempotent)."""
    if ENV_ID not in gym.registry:
        gym.register(
            id=ENV_ID,
            entry_point="client.sim.car_following:CarFollowingEnv",
            max_episode_steps=MAX_STEPS,
        )


register()
