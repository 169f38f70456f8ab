"""Failures with and without the shield, for any world: an environment, a fixed controller,
a shield configuration and a failure predicate.

Each world module gives :class:`World`: ``make(seed)`` builds the environment, ``controller(seed)``
the non-learning controller, ``config`` the shield configuration a user would write for it, and
``event(observation, info)`` the failure of a step (or None). An episode that fails ends there.
The shield learns from the first episode and revises from the episode its configuration says
(``reviser.activate_after_episodes``); failures are counted over the episodes after the
warm-up, per criterion, with and without the shield, on the same environment seeds.
"""

from __future__ import annotations

import json
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from app.core import Shield, ShieldConfig


@dataclass(frozen=True)
class World:
    """A world to try the shield in."""

    name: str
    make: Callable[[int], Any]  # seed -> environment with reset/step
    controller: Callable[[int], Callable[[Any], float]]  # seed -> observation -> action
    config: ShieldConfig
    event: Callable[[Any, dict[str, Any]], str | None]
    shield_observation: Callable[[Any], list[float]]
    max_steps: int


def run(world: World, seed: int, episodes: int, warmup: int,
        config: ShieldConfig | None) -> dict[str, Any]:
    """One run: ``episodes`` episodes of ``world`` from ``seed``; ``config`` None runs the
    controller alone. Returns the failures per criterion after the warm-up and the
    interventions."""
    env = world.make(seed)
    act = world.controller(seed)
    shield = None
    if config is not None:
        shield = Shield(config)
    failures: Counter[str] = Counter()
    revised = steps = 0
    for episode in range(episodes):
        observation, info = env.reset(seed=seed * 100_003 + episode)
        if hasattr(act, "reset"):
            act.reset()  # a controller with memory starts each episode afresh
        for _ in range(world.max_steps):
            proposed = float(act(observation))
            z = world.shield_observation(observation)
            applied = proposed
            if shield is not None:
                decision = shield.step(z, proposed, stream="0")
                applied = float(decision.action)
                if episode >= warmup:
                    revised += decision.revised
            observation, _, terminated, truncated, info = env.step(np.array([applied]))
            event = world.event(observation, info)
            if episode >= warmup:
                steps += 1
                if event is not None:
                    failures[event] += 1
            if event is not None or terminated or truncated:
                break
        if shield is not None:
            shield.step(world.shield_observation(observation), None, stream="0", done=True,
                        event=event)
    return {"failures": dict(failures), "total": sum(failures.values()),
            "episodes": episodes - warmup, "steps": steps, "revised": revised,
            "states": None if shield is None else shield.n_states}


def compare(world: World, seeds: list[int], episodes: int, warmup: int,
            config: ShieldConfig | None = None) -> dict[str, Any]:
    """The controller alone and shielded on each seed; totals and their ratio."""
    config = config or world.config
    rows = []
    for seed in seeds:
        alone = run(world, seed, episodes, warmup, None)
        shielded = run(world, seed, episodes, warmup, config)
        rows.append({"seed": seed, "alone": alone, "shielded": shielded})
    alone_total = sum(r["alone"]["total"] for r in rows)
    shield_total = sum(r["shielded"]["total"] for r in rows)
    return {"world": world.name, "episodes": episodes, "warmup": warmup, "seeds": seeds,
            "config": config.to_dict(), "runs": rows, "alone": alone_total,
            "shielded": shield_total,
            "ratio": shield_total / alone_total if alone_total else None}


def summary_line(result: dict[str, Any]) -> str:
    """One line: failures per 100 episodes after the warm-up, alone and shielded."""
    per = 100.0 / ((result["episodes"] - result["warmup"]) * len(result["seeds"]))
    alone = Counter[str]()
    shielded = Counter[str]()
    for r in result["runs"]:
        alone.update(r["alone"]["failures"])
        shielded.update(r["shielded"]["failures"])
    ratio = result["ratio"]
    return (f"{result['world']}: alone {result['alone'] * per:.1f} per 100 episodes "
            f"{dict(alone)}, shielded {result['shielded'] * per:.1f} {dict(shielded)}, "
            f"ratio {'-' if ratio is None else f'{ratio:.2f}'}, "
            f"states {[r['shielded']['states'] for r in result['runs']]}")


def dump(result: dict[str, Any]) -> str:
    """The result as one JSON document."""
    return json.dumps(result, indent=1)
