"""Run arms x runs x episodes of car following, each run in its own process, each shielded run
with its own model (in-process, or on a shield service reached over HTTP, WebSocket or batch).

Runs are deterministic for their seed, so an interrupted run is resumed by playing it again
from the start: the episodes already recorded must come out identical (checked), and only the
missing ones are appended.
"""

from __future__ import annotations

import dataclasses
import multiprocessing
import platform
import time
from collections import Counter
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, Protocol

import numpy as np

import app
from app.core import ShieldConfig
from client.agents.idm import PRESETS, RandomController
from client.experiment import records
from client.experiment.records import EpisodeRecord, RecordError
from client.shield import BatchShield, LocalShield, ShieldClient, ShieldSession, StepShield
from client.shield.wrapper import ShieldWrapper
from client.sim import lead
from client.sim.car_following import CarFollowingEnv, RewardConfig

CONTROLLERS = ("ddpg", "idm", "idm-aggressive", "random")
MODES = ("shield", "shadow")


@dataclass(frozen=True)
class ExperimentConfig:
    """One experiment. Every record file starts with it (the token excepted)."""

    arms: tuple[str, ...] = ("ddpg", "ddpg+shield")
    runs: int = 10
    episodes: int = 1500
    seed: int = 1000
    shield: str = "local"  # "local" or the URL of a shield service
    transport: Literal["http", "ws", "batch"] = "ws"
    lead: Literal["train", "evaluation", "epa", "synthetic"] = "train"
    shield_config: dict[str, Any] = field(default_factory=dict)
    ddpg: dict[str, Any] = field(default_factory=dict)
    reward: dict[str, Any] = field(default_factory=dict)
    model_prefix: str = "exp"

    def __post_init__(self) -> None:
        for arm in self.arms:
            parse_arm(arm)
        if self.runs < 1 or self.episodes < 1:
            raise ValueError("runs and episodes must be at least 1")

    def to_dict(self) -> dict[str, Any]:
        return {k: list(v) if isinstance(v, tuple) else v
                for k, v in dataclasses.asdict(self).items()}


def parse_arm(arm: str) -> tuple[str, str | None]:
    """``controller`` or ``controller+shield`` / ``controller+shadow``."""
    controller, _, mode = arm.partition("+")
    if controller not in CONTROLLERS or (mode and mode not in MODES):
        raise ValueError(f"unknown arm {arm!r}: a controller of {', '.join(CONTROLLERS)}, "
                         f"alone or with +shield or +shadow")
    return controller, mode or None


def run_seeds(seed: int, runs: int) -> list[int]:
    """Independent per-run seeds from one base seed."""
    return [int(s.generate_state(1)[0]) for s in np.random.SeedSequence(seed).spawn(runs)]


def versions() -> dict[str, str]:
    import gymnasium
    import torch

    return {"shield": app.__version__, "python": platform.python_version(),
            "numpy": np.__version__, "torch": torch.__version__,
            "gymnasium": gymnasium.__version__}


class Controller(Protocol):
    def act(self, observation: Any) -> float: ...


def profiles(source: str) -> lead.LeadProfiles:
    if source == "epa":
        return lead.epa()
    if source == "synthetic":
        return lead.synthetic(0, count=16)
    return lead.cmap(source)


def model_name(config: ExperimentConfig, arm: str, run: int) -> str:
    return f"{config.model_prefix}-{arm.replace('+', '-')}-{run}"


def make_shield(config: ExperimentConfig, arm: str, run: int, seed: int,
                token: str | None) -> StepShield:
    """A fresh, empty model for this run."""
    overrides = dict(config.shield_config)
    overrides["reviser"] = {**overrides.get("reviser", {}), "seed": seed}
    shield_config = ShieldConfig.from_dict(overrides)
    if config.shield == "local":
        return LocalShield(shield_config)
    name = model_name(config, arm, run)
    with ShieldClient(config.shield, token=token) as admin:
        if name in {m["name"] for m in admin.models()}:
            admin.delete_model(name)
        admin.create_model(name, shield_config.to_dict())
    if config.transport == "http":
        return ShieldClient(config.shield, token=token, model=name)
    if config.transport == "batch":
        return BatchShield(config.shield, token=token, model=name)
    return ShieldSession(config.shield, token=token, model=name)


def play(env: Any, agent: Controller, obs: Any, learner: Any | None) -> tuple[
        dict[str, Any], Any]:
    """One episode; returns its measurements and the last observation."""
    interventions: Counter[str] = Counter()
    would = 0
    diffs: list[float] = []
    episode_return = 0.0
    info: dict[str, Any] = {}
    steps = 0
    for steps in range(1, 801):  # noqa: B007 - steps is the episode length after the loop
        proposed = agent.act(obs)
        next_obs, reward, terminated, truncated, info = env.step(
            np.array([proposed], np.float32))
        decision = info.get("shield")
        executed = proposed if decision is None else decision.action
        if decision is not None and decision.revised:
            if decision.shadow:
                would += 1
            else:
                interventions[decision.verdict] += 1
        if learner is not None:
            learner.remember(obs, executed, reward, next_obs, terminated)
            learner.update()
        diffs.append(info["speed_difference"])
        episode_return += reward
        obs = next_obs
        if terminated or truncated:
            break
    done = info.get("shield_done")
    return {
        "steps": steps,
        "outcome": info.get("event") or "success",
        "interventions": dict(interventions),
        "revisions_would": would,
        "speed_diff_n": len(diffs),
        "speed_diff_mean": float(np.mean(diffs)),
        "speed_diff_var": float(np.var(diffs)),
        "episode_return": episode_return,
        "n_states": 0 if done is None else done.n_states,
    }, obs


def run_one(config: ExperimentConfig, arm: str, run: int, out: Path, token: str | None = None,
            progress: Any | None = None) -> int:
    """Play one run to ``config.episodes``; returns the number of episodes appended."""
    import torch

    torch.set_num_threads(1)
    torch.use_deterministic_algorithms(True)
    seed = run_seeds(config.seed, config.runs)[run]
    path = records.path_for(out, arm, run)
    identity = {k: v for k, v in config.to_dict().items() if k not in ("shield", "transport")}
    header = {"config": config.to_dict(), "identity": identity, "arm": arm, "run": run,
              "seed": seed, "versions": versions()}
    done = records.start(path, header)
    if len(done) >= config.episodes:
        return 0
    controller, mode = parse_arm(arm)
    env: Any = CarFollowingEnv(lead=profiles(config.lead), reward=RewardConfig(**config.reward))
    shield = make_shield(config, arm, run, seed, token) if mode else None
    if shield is not None:
        env = ShieldWrapper(env, shield, shadow=mode == "shadow")
    learner = None
    agent: Controller
    if controller == "ddpg":
        from client.agents.ddpg import DDPG, DDPGConfig

        learner = DDPG(DDPGConfig(**config.ddpg), seed)
        agent = learner
    elif controller == "random":
        agent = RandomController(seed)
    else:
        agent = PRESETS["aggressive" if controller == "idm-aggressive" else "normal"]
    appended = 0
    obs, _ = env.reset(seed=seed)
    try:
        for episode in range(1, config.episodes + 1):
            start = time.perf_counter()
            if learner is not None:
                learner.noise.reset()
            measured, obs = play(env, agent, obs, learner)
            record = EpisodeRecord(arm=arm, run=run, episode=episode, seed=seed,
                                   wall_s=time.perf_counter() - start, **measured)
            if episode <= len(done):
                old = done[episode - 1]
                if (old.steps, old.outcome, old.interventions) != (
                        record.steps, record.outcome, record.interventions):
                    raise RecordError(f"{path}: episode {episode} did not replay identically")
            else:
                records.append(path, record)
                appended += 1
                if progress is not None:
                    progress.put(1)
            obs, _ = env.reset()
    finally:
        if shield is not None:
            shield.close()
    return appended


def run_all(config: ExperimentConfig, out: Path, workers: int, token: str | None = None,
            bar: Any | None = None) -> int:
    """Every (arm, run) in its own process, at most ``workers`` at a time."""
    jobs = [(arm, run) for arm in config.arms for run in range(config.runs)]
    context = multiprocessing.get_context("spawn")
    with context.Manager() as manager, ProcessPoolExecutor(workers, mp_context=context) as pool:
        progress = manager.Queue()
        pending: set[Future[int]] = {
            pool.submit(run_one, config, arm, run, out, token, progress) for arm, run in jobs}
        appended = 0
        while pending:
            finished, pending = wait(pending, timeout=0.5, return_when=FIRST_COMPLETED)
            while not progress.empty():
                progress.get()
                if bar is not None:
                    bar.update(1)
            for future in finished:
                appended += future.result()
        return appended
