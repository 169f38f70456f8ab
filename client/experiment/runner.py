"""One run of an arm: car following for its episodes, its shielded steps on a model of its own
(in-process, or on a shield service reached over HTTP, WebSocket or batch), its records.

Runs are deterministic for their seed, so an interrupted run is resumed by playing it again
from the start: the episodes already recorded must come out identical (checked), and only the
missing ones are appended. Runs of DDPG can also step together (:mod:`.lockstep`), and an
experiment's runs play in worker processes (:mod:`.parallel`).
"""

from __future__ import annotations

import dataclasses
import gzip
import json
import platform
import time
from collections import Counter
from collections.abc import Callable, Sequence
from concurrent.futures import Executor, ThreadPoolExecutor
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import IO, Any, Literal, Protocol, TypeVar

import numpy as np

import app
from app.core import Shield, ShieldConfig, compiled
from app.service import codec
from client.agents.idm import PRESETS, RandomController
from client.experiment import records
from client.experiment.records import EpisodeRecord, RecordError
from client.experiment.trace import TraceWriter
from client.shield import BatchShield, LocalShield, ShieldClient, ShieldSession, StepShield
from client.shield.wrapper import ShieldWrapper
from client.sim import lead
from client.sim.car_following import CarFollowingEnv, RewardConfig

T = TypeVar("T")

CONTROLLERS = ("ddpg", "idm", "idm-aggressive", "random")
MODES = ("shield", "shadow")


@dataclass(frozen=True)
class ExperimentConfig:
    """One experiment. Every record file starts with it (the token excepted)."""

    arms: tuple[str, ...] = ("ddpg", "ddpg+shield")
    runs: int = 10
    episodes: int = 1500
    seed: int = 1000
    shield: str = "local"  # "local", or the URLs of shield services, comma-separated
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
        if "local" in self.shield_urls and self.shield != "local":
            raise ValueError("the shield is 'local' or a list of URLs, not both")

    @property
    def shield_urls(self) -> list[str]:
        return [url.strip() for url in self.shield.split(",")]

    def shield_url(self, run: int) -> str:
        """The service that holds run ``run``'s model: the URLs in turn, so that with one URL
        per run each run has a sidecar of its own."""
        urls = self.shield_urls
        return urls[run % len(urls)]

    def to_dict(self) -> dict[str, Any]:
        return {
            k: list(v) if isinstance(v, tuple) else v for k, v in dataclasses.asdict(self).items()
        }

    def identity(self) -> dict[str, Any]:
        """What makes the results: everything but where the shield runs and how it is
        reached."""
        return {k: v for k, v in self.to_dict().items() if k not in ("shield", "transport")}


def parse_arm(arm: str) -> tuple[str, str | None]:
    """``controller`` or ``controller+shield`` / ``controller+shadow``."""
    controller, _, mode = arm.partition("+")
    if controller not in CONTROLLERS or (mode and mode not in MODES):
        raise ValueError(
            f"unknown arm {arm!r}: a controller of {', '.join(CONTROLLERS)}, "
            f"alone or with +shield or +shadow"
        )
    return controller, mode or None


def run_seeds(seed: int, runs: int) -> list[int]:
    """Independent per-run seeds from one base seed."""
    return [int(s.generate_state(1)[0]) for s in np.random.SeedSequence(seed).spawn(runs)]


def versions() -> dict[str, str]:
    """The libraries and the processor a run computed with: the e-FSM's numbers are the same
    on every CPU (docs/algorithm.md, "Determinism"), but torch's follow the CPU, so records
    replay bit for bit only where they were written. ``core`` names the e-FSM this process
    runs (:func:`app.core.compiled.version`), which tells two methods apart where their
    configurations read the same: the shield's own when it runs in-process (a service names
    its own at ``GET /healthz``). ``cpu`` names the processor with the vector extensions torch
    and numpy use on it."""
    import gymnasium
    import torch

    return {
        "shield": app.__version__,
        "core": compiled.version(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "torch": torch.__version__,
        "gymnasium": gymnasium.__version__,
        "cpu": f"{processor()} (torch {torch.backends.cpu.get_cpu_capability()}, "
        f"numpy {numpy_simd()})",
    }


def processor() -> str:
    """The processor's model name, where the system tells it."""
    try:
        with open("/proc/cpuinfo") as f:
            names = [line.partition(":")[2].strip() for line in f if line.startswith("model name")]
    except OSError:
        names = []
    return names[0] if names else platform.processor() or platform.machine()


def numpy_simd() -> str:
    """The widest of numpy's dispatched SIMD levels this CPU runs (else its baseline)."""
    from numpy._core._multiarray_umath import (  # type: ignore[import-not-found]
        __cpu_baseline__,
        __cpu_dispatch__,
        __cpu_features__,
    )

    found = [name for name in __cpu_dispatch__ if __cpu_features__.get(name)]
    return str((found or list(__cpu_baseline__) or ["none"])[-1])


def replay_mismatch(path: Path, episode: int) -> str:
    """Why a recorded episode came out differently, naming each difference between the
    machine and build that wrote the records and this one: the e-FSM's sources, the hardware
    (whose arithmetic torch follows), the libraries; else a change of the code."""
    written = records.read(path)[0].get("versions") or {}
    here = versions()
    if "core" not in written:  # written before the headers named the e-FSM's sources
        del here["core"]

    def differs(name: str) -> bool:
        return name in here and written.get(name) != here[name]

    causes = []
    if differs("core"):
        causes.append(
            f"the e-FSM has changed since (core {written['core']} there, {here['core']} here)"
        )
    if differs("cpu"):
        there = written.get("cpu", "a processor not recorded")
        causes.append(
            f"the hardware differs (written on {there}, replayed on {here['cpu']}): "
            f"the controller's arithmetic follows the CPU"
        )
    libraries = [
        f"{name} {written.get(name, 'not recorded')} there, {value} here"
        for name, value in here.items()
        if name not in ("core", "cpu") and written.get(name) != value
    ]
    if libraries:
        causes.append(f"the libraries differ ({'; '.join(libraries)}): their arithmetic may too")
    if not causes:
        causes.append("written with these libraries on this processor: the code has changed since")
    return (
        f"{path}: episode {episode} did not replay identically ({'; '.join(causes)}); go "
        f"on where it was written, or start again with another --out"
    )


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


def shield_config(config: ExperimentConfig, seed: int) -> ShieldConfig:
    """The whole shield configuration of a run: the defaults, the overrides, the run's seed."""
    overrides = dict(config.shield_config)
    overrides["reviser"] = {**overrides.get("reviser", {}), "seed": seed}
    return ShieldConfig.from_dict(overrides)


def make_shield(
    config: ExperimentConfig,
    arm: str,
    run: int,
    seed: int,
    token: str | None,
    model: Any | None = None,
) -> StepShield:
    """A fresh, empty model for this run, or the model ``model`` (the exact state that
    :func:`model_state` gave)."""
    resolved = shield_config(config, seed)
    if config.shield == "local":
        local = LocalShield(resolved)
        if model is not None:
            local.shield = Shield.from_snapshot(codec.from_json(model))
        return local
    name, url = model_name(config, arm, run), config.shield_url(run)
    with ShieldClient(url, token=token) as admin:
        if model is not None:
            admin.restore(name, {"exact": model})
        else:
            if name in {m["name"] for m in admin.models()}:
                admin.delete_model(name)
            admin.create_model(name, resolved.to_dict())
    if config.transport == "http":
        return ShieldClient(url, token=token, model=name)
    if config.transport == "batch":
        return BatchShield(url, token=token, model=name)
    return ShieldSession(url, token=token, model=name)


def model_state(
    config: ExperimentConfig, arm: str, run: int, shield: StepShield, token: str | None
) -> Any:
    """The exact state of the run's model, as the service's snapshot gives it."""
    if isinstance(shield, LocalShield):
        return codec.to_json(shield.shield.snapshot())
    with ShieldClient(config.shield_url(run), token=token) as admin:
        return admin.snapshot(model_name(config, arm, run), tpm="none")["exact"]


class EpisodeMeter:
    """What one episode did, step by step."""

    def __init__(self) -> None:
        self.interventions: Counter[str] = Counter()
        self.would = 0
        self.diffs: list[float] = []
        self.episode_return = 0.0

    def add(self, proposed: float, reward: float, info: dict[str, Any]) -> float:
        """Count one step; returns the action that was executed."""
        decision = info.get("shield")  # the decision record as JSON-able data
        if decision is not None and decision["revised"]:
            if decision["shadow"]:
                self.would += 1
            else:
                self.interventions[decision["verdict"]] += 1
        self.diffs.append(info["speed_difference"])
        self.episode_return += reward
        return proposed if decision is None else float(decision["action"])

    def result(self, info: dict[str, Any]) -> dict[str, Any]:
        """The measurements of the finished episode, given the last step's info."""
        done = info.get("shield_done")
        return {
            "steps": len(self.diffs),
            "outcome": info.get("event") or "success",
            "interventions": dict(self.interventions),
            "revisions_would": self.would,
            "speed_diff_n": len(self.diffs),
            "speed_diff_mean": float(np.mean(self.diffs)),
            "speed_diff_var": float(np.var(self.diffs)),
            "episode_return": self.episode_return,
            "n_states": 0 if done is None else done["n_states"],
        }


def play(
    env: Any,
    agent: Controller,
    obs: Any,
    learner: Any | None,
    trace: Callable[[float, dict[str, Any]], None] | None = None,
    pool: Executor | None = None,
) -> tuple[dict[str, Any], Any]:
    """One episode; returns its measurements and the last observation. ``trace`` sees each
    step's proposal and info. A learner that updates first (``update_first``) updates
    while ``pool``, if given, steps the environment and its shield."""
    meter = EpisodeMeter()
    info: dict[str, Any] = {}
    first = learner is not None and learner.config.update_first
    for _ in range(800):
        proposed = agent.act(obs)
        action = np.array([proposed], np.float32)
        if first:
            next_obs, reward, terminated, truncated, info = while_updating(
                learner, pool, env.step, action
            )
        else:
            next_obs, reward, terminated, truncated, info = env.step(action)
        if trace is not None:
            trace(proposed, info)
        executed = meter.add(proposed, reward, info)
        if learner is not None:
            learner.remember(obs, executed, reward, next_obs, terminated)
            if not first:
                learner.update()
        obs = next_obs
        if terminated or truncated:
            break
    return meter.result(info), obs


def while_updating(learner: Any, pool: Executor | None, work: Callable[..., T], *args: Any) -> T:
    """``work(*args)`` and one update of ``learner``: at once where ``pool`` runs the work
    (a remote shield's answer is mostly waiting), else the update first. Both orders give the
    same result: the work does not touch the learner."""
    if pool is None:
        learner.update()
        return work(*args)
    pending = pool.submit(work, *args)
    learner.update()
    return pending.result()


def overlap_pool(learner: Any, shields: Sequence[StepShield | None]) -> Executor | None:
    """A thread to step remote shields in while a learner that updates first updates; none
    where there is nothing to wait for (no learner, the usual order, in-process shields)."""
    remote = any(s is not None and not isinstance(s, LocalShield) for s in shields)
    if learner is None or not learner.config.update_first or not remote:
        return None
    return ThreadPoolExecutor(1, thread_name_prefix="shield")


@dataclass
class Run:
    """One run of an arm: its seed, its record file, its environment (shielded or not)."""

    config: ExperimentConfig
    arm: str
    index: int
    seed: int
    path: Path
    recorded: list[EpisodeRecord]
    env: Any
    shield: StepShield | None
    claim: IO[bytes]
    token: str | None = None
    appended: int = 0
    trace: TraceWriter | None = None

    @classmethod
    def open(
        cls,
        config: ExperimentConfig,
        arm: str,
        index: int,
        out: Path,
        token: str | None,
        wrap: bool = True,
        trace: bool = False,
        learning: dict[str, Any] | None = None,
        model: Any | None = None,
    ) -> Run:
        """Open the run's records and environment; ``wrap=False`` leaves the shield (if any)
        to the caller instead of putting it in front of the environment; with ``trace`` a
        shielded run also writes its step trace. ``learning`` says how the learner ran
        (lockstep, device) for the header: it rounds differently, changes no configuration.
        ``model`` is the shield model to go on with (from a checkpoint), else a fresh one."""
        seed = run_seeds(config.seed, config.runs)[index]
        path = records.path_for(out, arm, index)
        identity = config.identity()
        _, mode = parse_arm(arm)
        header = {
            "config": config.to_dict(),
            "identity": identity,
            "arm": arm,
            "run": index,
            "seed": seed,
            "versions": versions(),
            "shield": shield_config(config, seed).to_dict() if mode else None,
            "reward": asdict(RewardConfig(**config.reward)),
            "learning": learning or {"lockstep": False, "device": "cpu"},
        }
        claim = records.claim(path)
        try:  # a refused file or an unreachable shield releases the run's file at once
            recorded = records.start(path, header, config.episodes)
            env: Any = CarFollowingEnv(
                lead=profiles(config.lead), reward=RewardConfig(**config.reward)
            )
            shield = None
            if mode and (len(recorded) < config.episodes or model is not None):
                shield = make_shield(config, arm, index, seed, token, model)
                if wrap:
                    env = ShieldWrapper(env, shield, shadow=mode == "shadow")
        except BaseException:
            records.release(claim, path)
            raise
        writer = TraceWriter(out, arm, index) if trace and shield is not None else None
        return cls(
            config, arm, index, seed, path, recorded, env, shield, claim, token, trace=writer
        )

    @property
    def complete(self) -> bool:
        return len(self.recorded) >= self.config.episodes

    def finish(
        self, episode: int, measured: dict[str, Any], wall_s: float, progress: Any | None
    ) -> None:
        """Check a replayed episode against its record, or append a new one."""
        record = EpisodeRecord(
            arm=self.arm, run=self.index, episode=episode, seed=self.seed, wall_s=wall_s, **measured
        )
        if episode <= len(self.recorded):
            old = self.recorded[episode - 1]
            if not records.same_course(old, record):
                raise RecordError(replay_mismatch(self.path, episode))
            return
        records.append(self.path, record)
        self.appended += 1
        if progress is not None:
            progress.put(1)

    def recorder(self, episode: int) -> Callable[[float, dict[str, Any]], None] | None:
        """The step recorder of ``episode`` when the run is traced."""
        return None if self.trace is None else self.trace.recorder(episode)

    def keep_model(self) -> None:
        """Write the run's shield model as it stands to ``OUT/models/`` (gzipped, the body that
        PUT /models/{name} takes), so that what the run learned outlives the process or the
        service that held it."""
        if self.shield is None:
            return
        model = model_state(self.config, self.arm, self.index, self.shield, self.token)
        path = self.path.parent.parent / "models" / f"{self.path.stem}.json.gz"
        path.parent.mkdir(exist_ok=True)
        partial = path.with_suffix(".partial")
        partial.write_bytes(gzip.compress(json.dumps({"exact": model}).encode(), mtime=0))
        partial.replace(path)

    def close(self) -> None:
        """Release the shield, the trace and the run's file."""
        if self.shield is not None:
            self.shield.close()
        if self.trace is not None:
            self.trace.close()
        records.release(self.claim, self.path)


def torch_for_one_core() -> None:
    import torch

    torch.set_num_threads(1)
    torch.use_deterministic_algorithms(True)


def run_one(
    config: ExperimentConfig,
    arm: str,
    run: int,
    out: Path,
    token: str | None = None,
    progress: Any | None = None,
    trace: bool = False,
    stop: Callable[[], bool] | None = None,
) -> int:
    """Play one run to ``config.episodes``, or until ``stop`` (asked after every episode) says
    to stop, and keep its shield model (:meth:`Run.keep_model`); returns the number of
    episodes appended. A stopped run goes on by replaying what it recorded."""
    torch_for_one_core()
    state = Run.open(config, arm, run, out, token, trace=trace)
    if state.complete:
        state.close()
        return 0
    controller, _ = parse_arm(arm)
    learner = None
    agent: Controller
    if controller == "ddpg":
        from client.agents.ddpg import DDPG, DDPGConfig

        learner = DDPG(DDPGConfig(**config.ddpg), state.seed)
        agent = learner
    elif controller == "random":
        agent = RandomController(state.seed)
    else:
        agent = PRESETS["aggressive" if controller == "idm-aggressive" else "normal"]
    obs, _ = state.env.reset(seed=state.seed)
    pool = overlap_pool(learner, [state.shield])
    try:
        for episode in range(1, config.episodes + 1):
            start = time.perf_counter()
            if learner is not None:
                learner.noise.reset()
            measured, obs = play(state.env, agent, obs, learner, state.recorder(episode), pool)
            state.finish(episode, measured, time.perf_counter() - start, progress)
            if stop is not None and stop():
                break
            obs, _ = state.env.reset()
        state.keep_model()
    finally:
        if pool is not None:
            pool.shutdown()
        state.close()
    return state.appended
