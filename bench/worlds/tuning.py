"""The tuning worlds: the project's own car-following simulator (``client/sim``) with its two
non-learning controllers, the aggressive IDM and the random one. Defaults are chosen here (and
on the DDPG protocol's tuning seeds), never on the held-out worlds beside this module.

``python -m bench.worlds --worlds tuning_idm,tuning_random --seeds 0,1``
"""

from __future__ import annotations

from typing import Any

from app.core import ShieldConfig
from bench.worlds.harness import World
from client.agents.idm import PRESETS, RandomController
from client.sim import lead as lead_data
from client.sim.car_following import MAX_STEPS, CarFollowingEnv

_LEAD = lead_data.cmap("train")


def _world(name: str, controller: Any) -> World:
    return World(name=name, make=lambda seed: CarFollowingEnv(lead=_LEAD),
                 controller=controller, config=ShieldConfig(),
                 event=lambda obs, info: info["event"],
                 shield_observation=lambda obs: [float(obs[0]), float(obs[1]), float(obs[2])],
                 max_steps=MAX_STEPS)


IDM_WORLD = _world("tuning-idm-aggressive", lambda seed: PRESETS["aggressive"].act)
RANDOM_WORLD = _world("tuning-random", lambda seed: RandomController(seed).act)
