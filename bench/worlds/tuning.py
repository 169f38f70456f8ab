"""The tuning worlds: the project's own car-following simulator (``client/sim``) with its
non-learning controllers: the aggressive IDM (it collides), the sluggish one (it falls behind),
the random one, and a collapsed one that always brakes fully, as a DDPG actor stuck at its
bound does (the shield has to drive). Defaults are chosen here (and
on the DDPG protocol's tuning seeds), never on the held-out worlds beside this module.

``python -m bench.worlds --seeds 0,1 \
    --worlds tuning_idm,tuning_sluggish,tuning_collapsed,tuning_random``
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
SLUGGISH_WORLD = _world("tuning-idm-sluggish", lambda seed: PRESETS["sluggish"].act)
COLLAPSED_WORLD = _world("tuning-collapsed", lambda seed: (lambda observation: -2.0))
RANDOM_WORLD = _world("tuning-random", lambda seed: RandomController(seed).act)
