"""A Gymnasium wrapper that puts a shield in front of any continuous-action environment."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from client.shield.base import StepShield


class ShieldWrapper(gym.Wrapper[Any, Any, Any, Any]):
    """Revise every proposed action before the environment sees it.

    The shield observes ``info["efsm_observation"]`` when the environment provides it (else the
    observation itself) and learns the failure named by ``info["event"]`` at the end of an
    episode. ``info["shield"]`` carries the decision of each step and
    ``info["shield_observation"]`` the observation it was made on; the action applied is the
    decision's. With ``shadow`` the shield learns and reports but never changes the action.
    """

    def __init__(self, env: gym.Env[Any, Any], shield: StepShield, stream: str = "0",
                 shadow: bool = False) -> None:
        super().__init__(env)
        self.shield = shield
        self.stream = stream
        self.shadow = shadow
        self._z: list[float] = []

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        observation, info = self.env.reset(**kwargs)
        self._z = _efsm(observation, info)
        return observation, info

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        proposed = float(np.asarray(action).reshape(-1)[0])
        z = self._z
        decision = self.shield.revise(z, proposed, stream=self.stream, shadow=self.shadow)
        applied = np.asarray([decision.action], dtype=np.float32)
        observation, reward, terminated, truncated, info = self.env.step(applied)
        self._z = _efsm(observation, info)
        info["shield"] = decision
        info["shield_observation"] = z
        if terminated or truncated:
            info["shield_done"] = self.shield.revise(self._z, None, stream=self.stream,
                                                     done=True, event=info.get("event"))
        return observation, float(reward), terminated, truncated, info


def _efsm(observation: Any, info: dict[str, Any]) -> list[float]:
    z = info.get("efsm_observation", observation)
    return [float(v) for v in np.asarray(z).reshape(-1)]
