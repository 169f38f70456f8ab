"""The tuning worlds: the project's own car-following simulator (``client/sim``) with its
non-learning controllers: the aggressive IDM (it collides), the sluggish one (it falls behind),
the random one, and a collapsed one that always brakes fully, as a DDPG actor stuck at its
bound does (the shield has to drive). Each comes twice: with the project's car-following
configuration, and (``_plain``) with the one a new user would write, the simulator's ranges
scaled linearly (headway over 200 m, no knee), which gives the model few, broad states as the
held-out worlds' configurations do. Beside them the tank (:mod:`bench.worlds.tank`), a world
of another make. Defaults are chosen here (and on the DDPG protocol's tuning seeds), never on
the held-out worlds beside this module.

``python -m bench.worlds --seeds 0,1 --worlds tuning``
"""

from __future__ import annotations

from typing import Any

from app.core import ObservationSpec, ShieldConfig
from bench.worlds import tank
from bench.worlds.harness import World
from client.agents.idm import PRESETS, RandomController
from client.sim import lead as lead_data
from client.sim.car_following import MAX_STEPS, CarFollowingEnv

_LEAD = lead_data.cmap("train")


PLAIN = ShieldConfig(observation=ObservationSpec(high=(35.0, 200.0, 35.0), knee=()))


def _world(name: str, controller: Any, config: ShieldConfig | None = None) -> World:
    return World(name=name, make=lambda seed: CarFollowingEnv(lead=_LEAD),
                 controller=controller, config=config or ShieldConfig(),
                 event=lambda obs, info: info["event"],
                 shield_observation=lambda obs: [float(obs[0]), float(obs[1]), float(obs[2])],
                 max_steps=MAX_STEPS)


_CONTROLLERS: dict[str, tuple[str, Any]] = {
    "idm": ("idm-aggressive", lambda seed: PRESETS["aggressive"].act),
    "sluggish": ("idm-sluggish", lambda seed: PRESETS["sluggish"].act),
    "collapsed": ("collapsed", lambda seed: (lambda observation: -2.0)),
    "random": ("random", lambda seed: RandomController(seed).act),
}

WORLDS: dict[str, World] = {"tuning_tank": tank.WORLD}
for _key, (_name, _controller) in _CONTROLLERS.items():
    WORLDS[f"tuning_{_key}"] = _world(f"tuning-{_name}", _controller)
    WORLDS[f"tuning_{_key}_plain"] = _world(f"tuning-{_name}-plain", _controller, PLAIN)
