"""The tuning worlds: the project's own car-following simulator (``client/sim``) with its
non-learning controllers: the aggressive IDM (it collides), the sluggish one (it falls behind),
the ordinary one reacting 2 s late (both), the random one, a collapsed one that always
brakes fully, as a DDPG actor stuck at its bound does, and one stuck at full acceleration (in
both the shield has to drive). Each comes
twice: with the project's car-following configuration, and (``_plain``) with the one a new
user would write, the simulator's ranges scaled linearly (headway over 200 m, no knee),
which gives the model few, broad states as the held-out worlds' configurations do. Beside
them two worlds of other makes: the tank (:mod:`bench.worlds.tank`) and the lander
(:mod:`bench.worlds.lander`), whose failure builds up over more steps than the horizon.

Three more, one of each kind issue #68 names, of other physics than the held-out worlds of
those kinds (``bench/heldout``), each with a direction per criterion as a new user would
configure it and (``_bounded``) with a ``Bound`` per failure as well; each controller was
calibrated alone to fail in 40-44% of episodes (seeds 0-8, 100 each), in both ways its
world names:

- ``tuning_dose`` (:mod:`bench.worlds.dose`), a slow failure on either side of one action: an
  insulin pump whose dose acts 1-3 hours later, ``low`` (less insulin) or ``high`` (more);
- ``tuning_cartpole`` (:mod:`bench.worlds.cartpole`), unstable, with a saving direction that
  depends on the state: a cart-pole on a short track, ``fall_right`` / ``fall_left`` (push
  that way) and ``off_right`` / ``off_left`` (push back);
- ``tuning_chemostat`` (:mod:`bench.worlds.chemostat`), a runaway and an extinction on either
  side of an unstable operating point: a cooperatively growing culture held by its dilution
  rate, ``bloom`` (more dilution) or ``washout`` (less).

Two of a public benchmark, for tuning and demonstration: ``highway`` and ``highway_too_slow``
(:mod:`bench.worlds.highway`), Farama's highway-env with the acceleration as the action, as
#68 measured it; they need the optional extra ``highway`` (highway-env), which only running
them asks for, and ``--worlds tuning`` leaves them out.

Defaults are chosen here (and on the DDPG protocol's tuning seeds), never on the held-out
worlds beside this module.

``python -m bench.worlds --seeds 0,1 --worlds tuning``
"""

from __future__ import annotations

from collections import deque
from typing import Any

import numpy as np

from app.core import ObservationSpec, ShieldConfig
from bench.worlds import cartpole, chemostat, dose, highway, lander, tank
from bench.worlds.harness import World
from client.agents.idm import PRESETS, RandomController
from client.sim import lead as lead_data
from client.sim.car_following import MAX_STEPS, CarFollowingEnv

_LEAD = lead_data.cmap("train")


LATE_STEPS = 8  # 2 s at the simulator's 0.25 s step


class LateIDM:
    """The ordinary IDM preset acting on what it saw ``LATE_STEPS`` steps ago."""

    def __init__(self, seed: int) -> None:
        self.seen: deque[np.ndarray] = deque(maxlen=LATE_STEPS + 1)

    def reset(self) -> None:
        self.seen.clear()

    def __call__(self, observation: np.ndarray) -> float:
        self.seen.append(np.array(observation, dtype=np.float64))
        return PRESETS["normal"].act(self.seen[0])


PLAIN = ShieldConfig(observation=ObservationSpec(high=(35.0, 200.0, 35.0), knee=()))


def _world(name: str, controller: Any, config: ShieldConfig | None = None) -> World:
    return World(
        name=name,
        make=lambda seed: CarFollowingEnv(lead=_LEAD),
        controller=controller,
        config=config or ShieldConfig(),
        event=lambda obs, info: info["event"],
        shield_observation=lambda obs: [float(obs[0]), float(obs[1]), float(obs[2])],
        max_steps=MAX_STEPS,
    )


_CONTROLLERS: dict[str, tuple[str, Any]] = {
    "idm": ("idm-aggressive", lambda seed: PRESETS["aggressive"].act),
    "sluggish": ("idm-sluggish", lambda seed: PRESETS["sluggish"].act),
    "late": ("idm-late", LateIDM),
    "collapsed": ("collapsed", lambda seed: lambda observation: -2.0),
    "flat_out": ("flat-out", lambda seed: lambda observation: 2.0),
    "random": ("random", lambda seed: RandomController(seed).act),
}

WORLDS: dict[str, World] = {"tuning_tank": tank.WORLD, "tuning_lander": lander.WORLD}
for _module in (dose, cartpole, chemostat):
    _key = _module.__name__.rsplit(".", 1)[-1]
    WORLDS[f"tuning_{_key}"] = _module.WORLD
    WORLDS[f"tuning_{_key}_bounded"] = _module.WORLD_BOUNDED
for _key, (_name, _controller) in _CONTROLLERS.items():
    WORLDS[f"tuning_{_key}"] = _world(f"tuning-{_name}", _controller)
    WORLDS[f"tuning_{_key}_plain"] = _world(f"tuning-{_name}-plain", _controller, PLAIN)
# highway-env's worlds: built without it (it is imported when one is run), not in "tuning"
WORLDS["highway"] = highway.WORLD
WORLDS["highway_too_slow"] = highway.WORLD_TOO_SLOW
