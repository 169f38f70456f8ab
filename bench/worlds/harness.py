"""Failures with and without the shield, for any world: an environment, a fixed controller,
a shield configuration and a failure predicate.

Each world module gives :class:`World`: ``make(seed)`` builds the environment, ``controller(seed)``
the non-learning controller, ``config`` the shield configuration a user would write for it, and
``event(observation, info)`` the failure of a step (or None). An episode that fails ends there.
The shield learns from the first episode and revises from the episode its configuration says
(``reviser.activate_after_episodes``); failures are counted over the episodes after the
warm-up, per criterion, with and without the shield, each episode from the same seeds
(:func:`controller_seed`), and within
the warm-up too (the shield must cost nothing while it learns), beside the share of steps it
revised and the controller's own task figure (a shield that takes the task over has failed).
"""

from __future__ import annotations

import json
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np

from app.core import Shield, ShieldConfig


class Spaces(gym.Env[Any, Any]):
    """An environment that is only its two spaces: all that ``config_for`` reads of a world
    whose environment is built per seed."""

    def __init__(self, observation_space: gym.Space[Any], action_space: gym.Space[Any]) -> None:
        self.observation_space = observation_space
        self.action_space = action_space


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


def plain_world(
    name: str,
    make: Callable[[], Any],
    controller: Callable[[int], Callable[[Any], float]],
    config: ShieldConfig,
    max_steps: int,
) -> World:
    """A world whose environment (``make()``, the same for every seed: ``reset(seed)`` draws)
    names a step's failure in ``info["event"]`` and whose whole observation the shield sees."""
    return World(
        name=name,
        make=lambda seed: make(),
        controller=controller,
        config=config,
        event=lambda observation, info: info["event"],
        shield_observation=lambda observation: [float(v) for v in observation],
        max_steps=max_steps,
    )


def run(
    world: World, seed: int, episodes: int, warmup: int, config: ShieldConfig | None
) -> dict[str, Any]:
    """One run: ``episodes`` episodes of ``world`` from ``seed``; ``config`` None runs the
    controller alone.

    Returns the failures per criterion after the warm-up (``failures``, ``total``) and within
    it (``early``: what learning costs), and how much the shield took over after the warm-up:
    the share of steps it revised, the mean size of a revision (``|applied - proposed|``) and
    the controller's own task figure, the mean of ``info["task"]`` per step where the world
    reports one (lower is better; None where it reports none)."""
    env = world.make(seed)
    shield = None
    if config is not None:
        shield = Shield(config)
    failures: Counter[str] = Counter()
    early: Counter[str] = Counter()
    revised = steps = 0
    revision = task = 0.0
    tasks = 0
    for episode in range(episodes):
        observation, info = env.reset(seed=seed * 100_003 + episode)
        act = world.controller(controller_seed(seed, episode))
        if hasattr(act, "reset"):
            act.reset()
        counted = episode >= warmup
        for _ in range(world.max_steps):
            proposed = float(act(observation))
            z = world.shield_observation(observation)
            applied = proposed
            if shield is not None:
                decision = shield.step(z, proposed, stream="0")
                assert decision.action is not None  # a step with a proposal has an action
                applied = decision.action
                if counted and decision.revised:
                    revised += 1
                    revision += abs(applied - proposed)
            observation, _, terminated, truncated, info = env.step(np.array([applied]))
            event = world.event(observation, info)
            if counted:
                steps += 1
                if "task" in info:
                    task += float(info["task"])
                    tasks += 1
            if event is not None:
                (failures if counted else early)[event] += 1
            if event is not None or terminated or truncated:
                break
        if shield is not None:
            shield.step(
                world.shield_observation(observation), None, stream="0", done=True, event=event
            )
    return {
        "failures": dict(failures),
        "total": sum(failures.values()),
        "early": dict(early),
        "early_total": sum(early.values()),
        "episodes": episodes - warmup,
        "steps": steps,
        "revised": revised,
        "revised_share": revised / steps if steps else 0.0,
        "mean_revision": revision / revised if revised else 0.0,
        "task": task / tasks if tasks else None,
        "states": None if shield is None else shield.n_states,
    }


def controller_seed(seed: int, episode: int) -> int:
    """The seed of the controller of one episode of a run. Each episode builds its controller
    afresh from ``(seed, episode)``, as its environment resets from them: an episode the shield
    leaves alone is then the same episode as the controller's alone, whatever happened before
    it, and the shielded and the lone run differ only where the shield acted (common random
    numbers; a controller drawing from one generator over the whole run would make every
    episode after the first revision a different lottery)."""
    return int(np.random.SeedSequence((seed, episode)).generate_state(1)[0])


def ratio(shielded: int, alone: int) -> float | None:
    """Failures shielded over failures alone; None where the controller alone never failed
    (then any shielded failure is harm, which :func:`compare` flags on its own)."""
    return shielded / alone if alone else None


def compare(
    world: World, seeds: list[int], episodes: int, warmup: int, config: ShieldConfig | None = None
) -> dict[str, Any]:
    """The controller alone and shielded on each seed: totals, their ratio, the worst seed's
    ratio and the seeds on which the shield did harm (more failures than alone, after the
    warm-up or within it)."""
    config = config or world.config
    rows: list[dict[str, Any]] = []
    for seed in seeds:
        alone = run(world, seed, episodes, warmup, None)
        shielded = run(world, seed, episodes, warmup, config)
        rows.append(
            {
                "seed": seed,
                "alone": alone,
                "shielded": shielded,
                "ratio": ratio(shielded["total"], alone["total"]),
            }
        )
    alone_total = sum(r["alone"]["total"] for r in rows)
    shield_total = sum(r["shielded"]["total"] for r in rows)
    ratios = [r["ratio"] for r in rows if r["ratio"] is not None]
    return {
        "world": world.name,
        "episodes": episodes,
        "warmup": warmup,
        "seeds": seeds,
        "config": config.to_dict(),
        "runs": rows,
        "alone": alone_total,
        "shielded": shield_total,
        "ratio": ratio(shield_total, alone_total),
        "worst_seed_ratio": max(ratios, default=None),
        "harmed_seeds": [r["seed"] for r in rows if r["shielded"]["total"] > r["alone"]["total"]],
        "early_harmed_seeds": [
            r["seed"] for r in rows if r["shielded"]["early_total"] > r["alone"]["early_total"]
        ],
        "alone_early": sum(r["alone"]["early_total"] for r in rows),
        "shielded_early": sum(r["shielded"]["early_total"] for r in rows),
    }


def summary_line(result: dict[str, Any]) -> str:
    """One line: failures per 100 episodes after the warm-up, alone and shielded, the ratio
    and the worst seed's, the warm-up's failures, the share of steps revised and the task
    figure alone and shielded."""
    per = 100.0 / ((result["episodes"] - result["warmup"]) * len(result["seeds"]))
    alone = Counter[str]()
    shielded = Counter[str]()
    for r in result["runs"]:
        alone.update(r["alone"]["failures"])
        shielded.update(r["shielded"]["failures"])

    def figure(value: float | None) -> str:
        return "-" if value is None else f"{value:.2f}"

    runs = result["runs"]
    revised = sum(r["shielded"]["revised"] for r in runs)
    steps = sum(r["shielded"]["steps"] for r in runs)
    tasks = [
        (r["alone"]["task"], r["shielded"]["task"]) for r in runs if r["alone"]["task"] is not None
    ]
    task = (
        f", task {sum(a for a, _ in tasks) / len(tasks):.3g} alone, "
        f"{sum(s for _, s in tasks) / len(tasks):.3g} shielded"
        if tasks
        else ""
    )
    harmed = result["harmed_seeds"] + [f"{s} (warm-up)" for s in result["early_harmed_seeds"]]
    return (
        f"{result['world']}: alone {result['alone'] * per:.1f} per 100 episodes "
        f"{dict(alone)}, shielded {result['shielded'] * per:.1f} {dict(shielded)}, "
        f"ratio {figure(result['ratio'])} (worst seed {figure(result['worst_seed_ratio'])}"
        f", worse than alone on {harmed or 'none'}), warm-up {result['alone_early']} alone"
        f" vs {result['shielded_early']}, revised {revised / max(steps, 1):.1%}{task}, "
        f"states {[r['shielded']['states'] for r in runs]}"
    )


def dump(result: dict[str, Any]) -> str:
    """The result as one JSON document."""
    return json.dumps(result, indent=1)
