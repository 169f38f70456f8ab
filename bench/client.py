"""The client's costs: simulator steps, a DDPG update, and shielded training per transport.

* simulator steps per second alone (random actions);
* one DDPG update (batch 64, the configured networks), single-threaded torch;
* the wall time of the same shielded DDPG training (seed 0, the reviser active from the start
  so every step is inspected) in-process and over WebSocket, HTTP and the batch route of a
  shield service in its own process, as ratios to in-process, in the usual order (update
  after the step) and with ``update_first`` (the update runs while the service answers);
* 10 DDPG runs trained one after the other against the same 10 runs in lockstep with one
  vectorised update: with in-process shields, and against the service (one after the other
  over WebSocket, lockstep over the batch route) in both orders, with the steps they took.

Medians over rounds.

    python bench/client.py --rounds 3 --episodes 8
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from app.core import ShieldConfig  # noqa: E402
from client.__main__ import service  # noqa: E402
from client.agents.ddpg import DDPG, DDPGConfig  # noqa: E402
from client.experiment.runner import overlap_pool, play  # noqa: E402
from client.shield import (  # noqa: E402
    BatchShield,
    LocalShield,
    ShieldClient,
    ShieldSession,
    StepShield,
)
from client.shield.wrapper import ShieldWrapper  # noqa: E402
from client.sim import lead  # noqa: E402
from client.sim.car_following import CarFollowingEnv  # noqa: E402

SHIELD = {"reviser": {"activate_after_episodes": 0}}


def simulator_steps_per_second(steps: int = 20_000) -> float:
    env = CarFollowingEnv(lead=lead.cmap("train"))
    env.reset(seed=0)
    actions = np.random.default_rng(0).uniform(-2, 2, steps).astype(np.float32)
    start = time.perf_counter()
    for a in actions:
        *_, terminated, truncated, _ = env.step(a[None])
        if terminated or truncated:
            env.reset()
    return steps / (time.perf_counter() - start)


def update_ms(learner: DDPG | Any, memories: list[DDPG], updates: int) -> float:
    """Milliseconds per ``learner.update()`` once every memory holds 1000 transitions."""
    rng = np.random.default_rng(0)
    for memory in memories:
        for _ in range(1000):
            obs = rng.uniform(0, 30, 4).astype(np.float32)
            memory.remember(obs, 0.0, -1.0, obs, False)
    learner.update()
    start = time.perf_counter()
    for _ in range(updates):
        learner.update()
    return (time.perf_counter() - start) / updates * 1e3


def ddpg_update_ms() -> float:
    agent = DDPG(DDPGConfig(warmup=64), 0)
    return update_ms(agent, [agent], 500)


def ensemble_update_ms(members: int) -> float:
    """One vectorised update of ``members`` DDPG learners."""
    from client.agents.ensemble import DDPGEnsemble

    ensemble = DDPGEnsemble(DDPGConfig(warmup=64), list(range(members)))
    return update_ms(ensemble, ensemble.members, 200)


def training(shield: StepShield, episodes: int, update_first: bool) -> tuple[float, int]:
    """Seconds and steps of a shielded DDPG training (``update_first``: the learner updates
    while a remote shield answers)."""
    env = ShieldWrapper(CarFollowingEnv(lead=lead.cmap("train")), shield)
    agent = DDPG(DDPGConfig(warmup=256, update_first=update_first), 0)
    pool = overlap_pool(agent, [shield])
    obs, _ = env.reset(seed=0)
    steps = 0
    start = time.perf_counter()
    for _ in range(episodes):
        measured, obs = play(env, agent, obs, agent, pool=pool)
        steps += measured["steps"]
        obs, _ = env.reset()
    seconds = time.perf_counter() - start
    if pool is not None:
        pool.shutdown()
    return seconds, steps


def lockstep_against_separate(
    runs: int, episodes: int, url: str = "local", update_first: bool = False
) -> dict[str, float]:
    """Seconds for ``runs`` x ``episodes`` of ddpg+shield, one run after another and in
    lockstep, with their steps (all runs' one after another; the longest run's in lockstep,
    one step of every run each); with a service ``url``, separate runs use WebSocket and
    lockstep the batch route (one request per step for every run)."""
    from client.experiment import records
    from client.experiment.lockstep import run_lockstep
    from client.experiment.runner import ExperimentConfig, run_one

    def steps(out: str) -> list[int]:
        return [
            sum(r.steps for r in records.read(records.path_for(Path(out), "ddpg+shield", run))[1])
            for run in range(runs)
        ]

    config = ExperimentConfig(
        arms=("ddpg+shield",),
        runs=runs,
        episodes=episodes,
        seed=0,
        ddpg={"warmup": 256, "update_first": update_first},
        shield=url,
        transport="ws",
        shield_config={"reviser": {"activate_after_episodes": 0}},
    )
    with tempfile.TemporaryDirectory() as separate, tempfile.TemporaryDirectory() as together:
        start = time.perf_counter()
        for run in range(runs):
            run_one(config, "ddpg+shield", run, Path(separate))
        one_by_one = time.perf_counter() - start
        start = time.perf_counter()
        run_lockstep(dataclasses.replace(config, transport="batch"), "ddpg+shield", Path(together))
        return {
            "separate_s": one_by_one,
            "lockstep_s": time.perf_counter() - start,
            "separate_steps": sum(steps(separate)),
            "lockstep_steps": max(steps(together)),
        }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--episodes", type=int, default=8)
    parser.add_argument("--json")
    args = parser.parse_args()
    torch.set_num_threads(1)

    sim = statistics.median(simulator_steps_per_second() for _ in range(args.rounds))
    update = statistics.median(ddpg_update_ms() for _ in range(args.rounds))
    ensemble = statistics.median(ensemble_update_ms(10) for _ in range(args.rounds))
    orders = {"usual": False, "update first": True}
    times: dict[tuple[str, str], list[float]] = {}
    steps: dict[tuple[str, str], int] = {}
    with tempfile.TemporaryDirectory() as data, service(Path(data) / "shield") as url:
        for r in range(args.rounds):
            for order, first in orders.items():
                tag = f"{r}-{int(first)}"
                with ShieldClient(url) as admin:
                    for t in ("ws", "http", "batch"):
                        admin.create_model(f"bench-{t}-{tag}", SHIELD)
                shields: dict[str, StepShield] = {
                    "in-process": LocalShield(ShieldConfig.from_dict(SHIELD)),
                    "ws": ShieldSession(url, model=f"bench-ws-{tag}"),
                    "http": ShieldClient(url, model=f"bench-http-{tag}"),
                    "batch": BatchShield(url, model=f"bench-batch-{tag}"),
                }
                for name, shield in shields.items():
                    seconds, n = training(shield, args.episodes, first)
                    shield.close()
                    times.setdefault((order, name), []).append(seconds)
                    steps[order, name] = n
        remote = {
            order: [lockstep_against_separate(10, 3, url, first) for _ in range(args.rounds)]
            for order, first in orders.items()
        }
    local = {
        order: [lockstep_against_separate(10, 3, "local", first) for _ in range(args.rounds)]
        for order, first in orders.items()
    }
    results: dict[str, Any] = {
        "simulator_steps_per_s": sim,
        "ddpg_update_ms": update,
        "ensemble_update_ms_10": ensemble,
        "training": {},
    }
    print(
        f"\nseed 0; {args.rounds} rounds; {args.episodes} training episodes each; "
        f"{platform.machine()}, Python {platform.python_version()}, torch "
        f"{torch.__version__} (1 thread)\n"
    )
    print(f"simulator alone: {sim:,.0f} steps per second")
    print(f"DDPG update (batch 64, 64x64 networks): {update:.2f} ms")
    print(
        f"one vectorised update of 10 learners: {ensemble:.2f} ms "
        f"({10 * update / ensemble:.1f}x faster than 10 updates)\n"
    )
    print("| order | shield reached | training wall time (s) | steps | vs in-process, same order |")
    print("|---|---|---:|---:|---:|")
    for (order, name), values in times.items():
        median = statistics.median(values)
        base = statistics.median(times[order, "in-process"])
        results["training"][f"{order}: {name}"] = {
            "seconds": median,
            "steps": steps[order, name],
            "ratio": median / base,
        }
        print(f"| {order} | {name} | {median:.1f} | {steps[order, name]} | {median / base:.2f}x |")
    print(
        "\n10 runs x 3 episodes of ddpg+shield, one after another (WebSocket against the "
        "service) and in lockstep (the batch route):\n"
    )
    print(
        "| order | shield | one after another (s) | ms a step | lockstep (s) "
        "| ms a lockstep step | lockstep vs in-process, same order |"
    )
    print("|---|---|---:|---:|---:|---:|---:|")
    results["lockstep"] = {}
    for order in orders:
        base = statistics.median(r["lockstep_s"] for r in local[order])
        for where, rows in (("in-process", local[order]), ("service", remote[order])):
            m = {key: statistics.median(r[key] for r in rows) for key in rows[0]}
            results["lockstep"][f"{order}: {where}"] = m
            print(
                f"| {order} | {where} | {m['separate_s']:.1f} "
                f"| {1e3 * m['separate_s'] / m['separate_steps']:.2f} | {m['lockstep_s']:.1f} "
                f"| {1e3 * m['lockstep_s'] / m['lockstep_steps']:.2f} "
                f"| {m['lockstep_s'] / base:.2f}x |"
            )
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()
