"""Run arms x runs x episodes of car following, each run in its own process, each shielded run
with its own model (in-process, or on a shield service reached over HTTP, WebSocket or batch).

Runs are deterministic for their seed, so an interrupted run is resumed by playing it again
from the start: the episodes already recorded must come out identical (checked), and only the
missing ones are appended. Lockstep groups also write checkpoints (:mod:`.checkpoint`) and
continue from the latest instead of from the start.
"""

from __future__ import annotations

import ctypes
import dataclasses
import gzip
import json
import multiprocessing
import os
import platform
import signal
import sys
import time
from collections import Counter
from collections.abc import Callable, Sequence
from concurrent.futures import (
    FIRST_COMPLETED,
    Future,
    ProcessPoolExecutor,
    ThreadPoolExecutor,
    wait,
)
from dataclasses import dataclass, field
from functools import partial
from multiprocessing.managers import SyncManager
from pathlib import Path
from typing import IO, Any, Literal, Protocol

import numpy as np

import app
from app.core import Shield, ShieldConfig
from app.service import codec
from client.agents.idm import PRESETS, RandomController
from client.experiment import checkpoint, records
from client.experiment.records import EpisodeRecord, RecordError
from client.experiment.trace import TraceWriter
from client.shield import BatchShield, LocalShield, ShieldClient, ShieldSession, StepShield
from client.shield.remote import step_body
from client.shield.wrapper import ShieldWrapper
from client.sim import lead
from client.sim.car_following import CarFollowingEnv, RewardConfig

PR_SET_PDEATHSIG = 1  # prctl(2)
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
        return {k: list(v) if isinstance(v, tuple) else v
                for k, v in dataclasses.asdict(self).items()}

    def identity(self) -> dict[str, Any]:
        """What makes the results: everything but where the shield runs and how it is
        reached."""
        return {k: v for k, v in self.to_dict().items() if k not in ("shield", "transport")}


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
    """The libraries and the processor a run computed with: floating point can come out
    differently on another processor or build, and then a run does not replay."""
    import gymnasium
    import torch

    return {"shield": app.__version__, "python": platform.python_version(),
            "numpy": np.__version__, "torch": torch.__version__,
            "gymnasium": gymnasium.__version__,
            "cpu": f"{processor()} ({torch.backends.cpu.get_cpu_capability()})"}


def processor() -> str:
    """The processor's model name, where the system tells it."""
    try:
        with open("/proc/cpuinfo") as f:
            names = [line.partition(":")[2].strip() for line in f
                     if line.startswith("model name")]
    except OSError:
        names = []
    return names[0] if names else platform.processor() or platform.machine()


def replay_mismatch(path: Path, episode: int) -> str:
    """Why a recorded episode came out differently: the libraries or the processor that
    wrote the records, where they differ from this machine's, else a change of the code."""
    written = records.read(path)[0].get("versions") or {}
    here = versions()
    changed = [f"{name} {written.get(name, 'not recorded')} there, {value} here"
               for name, value in here.items() if written.get(name) != value]
    if changed:
        cause = f"written with {'; '.join(changed)}: arithmetic differs between machines and builds"
    else:
        cause = "written with these libraries on this processor: the code has changed since"
    return (f"{path}: episode {episode} did not replay identically ({cause}); go on where it "
            f"was written, or start again with another --out")


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


def make_shield(config: ExperimentConfig, arm: str, run: int, seed: int,
                token: str | None, model: Any | None = None) -> StepShield:
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


def model_state(config: ExperimentConfig, arm: str, run: int, shield: StepShield,
                token: str | None) -> Any:
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
        decision = info.get("shield")
        if decision is not None and decision.revised:
            if decision.shadow:
                self.would += 1
            else:
                self.interventions[decision.verdict] += 1
        self.diffs.append(info["speed_difference"])
        self.episode_return += reward
        return proposed if decision is None else float(decision.action)

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
            "n_states": 0 if done is None else done.n_states,
        }


def play(env: Any, agent: Controller, obs: Any, learner: Any | None,
         trace: Callable[[float, dict[str, Any]], None] | None = None) -> tuple[
        dict[str, Any], Any]:
    """One episode; returns its measurements and the last observation. ``trace`` sees each
    step's proposal and info."""
    meter = EpisodeMeter()
    info: dict[str, Any] = {}
    for _ in range(800):
        proposed = agent.act(obs)
        next_obs, reward, terminated, truncated, info = env.step(
            np.array([proposed], np.float32))
        if trace is not None:
            trace(proposed, info)
        executed = meter.add(proposed, reward, info)
        if learner is not None:
            learner.remember(obs, executed, reward, next_obs, terminated)
            learner.update()
        obs = next_obs
        if terminated or truncated:
            break
    return meter.result(info), obs


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
    def open(cls, config: ExperimentConfig, arm: str, index: int, out: Path,
             token: str | None, wrap: bool = True, trace: bool = False,
             learning: dict[str, Any] | None = None, model: Any | None = None) -> Run:
        """Open the run's records and environment; ``wrap=False`` leaves the shield (if any)
        to the caller instead of putting it in front of the environment; with ``trace`` a
        shielded run also writes its step trace. ``learning`` says how the learner ran
        (lockstep, device) for the header: it rounds differently, changes no configuration.
        ``model`` is the shield model to go on with (from a checkpoint), else a fresh one."""
        seed = run_seeds(config.seed, config.runs)[index]
        path = records.path_for(out, arm, index)
        identity = config.identity()
        _, mode = parse_arm(arm)
        header = {"config": config.to_dict(), "identity": identity, "arm": arm, "run": index,
                  "seed": seed, "versions": versions(),
                  "shield": shield_config(config, seed).to_dict() if mode else None,
                  "learning": learning or {"lockstep": False, "device": "cpu"}}
        claim = records.claim(path)
        try:  # a refused file or an unreachable shield releases the run's file at once
            recorded = records.start(path, header, config.episodes)
            env: Any = CarFollowingEnv(lead=profiles(config.lead),
                                       reward=RewardConfig(**config.reward))
            shield = None
            if mode and (len(recorded) < config.episodes or model is not None):
                shield = make_shield(config, arm, index, seed, token, model)
                if wrap:
                    env = ShieldWrapper(env, shield, shadow=mode == "shadow")
        except BaseException:
            records.release(claim, path)
            raise
        writer = TraceWriter(out, arm, index) if trace and shield is not None else None
        return cls(config, arm, index, seed, path, recorded, env, shield, claim, token,
                   trace=writer)

    @property
    def complete(self) -> bool:
        return len(self.recorded) >= self.config.episodes

    def finish(self, episode: int, measured: dict[str, Any], wall_s: float,
               progress: Any | None) -> None:
        """Check a replayed episode against its record, or append a new one."""
        record = EpisodeRecord(arm=self.arm, run=self.index, episode=episode, seed=self.seed,
                               wall_s=wall_s, **measured)
        if episode <= len(self.recorded):
            old = self.recorded[episode - 1]
            if (old.steps, old.outcome, old.interventions) != (
                    record.steps, record.outcome, record.interventions):
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


def _torch_for_one_core() -> None:
    import torch

    torch.set_num_threads(1)
    torch.use_deterministic_algorithms(True)


def run_one(config: ExperimentConfig, arm: str, run: int, out: Path, token: str | None = None,
            progress: Any | None = None, trace: bool = False,
            stop: Callable[[], bool] | None = None) -> int:
    """Play one run to ``config.episodes``, or until ``stop`` (asked after every episode) says
    to stop, and keep its shield model (:meth:`Run.keep_model`); returns the number of
    episodes appended. A stopped run goes on by replaying what it recorded."""
    _torch_for_one_core()
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
    try:
        for episode in range(1, config.episodes + 1):
            start = time.perf_counter()
            if learner is not None:
                learner.noise.reset()
            measured, obs = play(state.env, agent, obs, learner, state.recorder(episode))
            state.finish(episode, measured, time.perf_counter() - start, progress)
            if stop is not None and stop():
                break
            obs, _ = state.env.reset()
        state.keep_model()
    finally:
        state.close()
    return state.appended


@dataclass
class Place:
    """Where a lockstep run stands: its episode, what that episode did so far, and its last
    observations (the controller's and the e-FSM's)."""

    episode: int
    meter: EpisodeMeter
    started: float
    obs: Any
    z: Any

    @classmethod
    def start(cls, run: Run) -> Place:
        obs, info = run.env.reset(seed=run.seed)
        return cls(1, EpisodeMeter(), time.perf_counter(), obs, info["efsm_observation"])

    def state(self, run: Run) -> dict[str, Any]:
        """The place with the simulator's state and the shield model's, for a checkpoint."""
        return {"episode": self.episode, "meter": self.meter, "obs": self.obs, "z": self.z,
                "elapsed": time.perf_counter() - self.started, "env": run.env.state(),
                "model": None if run.shield is None else
                model_state(run.config, run.arm, run.index, run.shield, run.token)}

    @classmethod
    def restore(cls, run: Run, state: dict[str, Any]) -> Place:
        run.env.restore(state["env"])
        return cls(state["episode"], state["meter"], time.perf_counter() - state["elapsed"],
                   state["obs"], state["z"])


def past(deadline: float) -> bool:
    """Whether the wall clock has passed ``deadline`` (seconds since the epoch)."""
    return time.time() >= deadline


def run_lockstep(config: ExperimentConfig, arm: str, out: Path, token: str | None = None,
                 progress: Any | None = None, trace: bool = False,
                 indices: Sequence[int] | None = None, device: str = "cpu",
                 checkpoint_every: float | None = None,
                 stop: Callable[[], bool] | None = None) -> int:
    """The runs of a DDPG arm (all, or those ``indices``) in one process, stepping together: one
    batched DDPG update for all runs per step (:class:`~client.agents.ensemble.DDPGEnsemble`,
    on ``device``), and one round of shield requests per step: with the batch transport one
    request carrying a step of every run's model, over WebSocket every run's step sent before
    any reply is read. Each run sees the same sequence as :func:`run_one` (act, shield, step,
    remember, update); results agree within the rounding of batched arithmetic.

    The group saves a checkpoint every ``checkpoint_every`` seconds, and when ``stop`` (asked
    after every step) says to stop, before returning; a group with a checkpoint continues from
    it. Done or stopped, the runs keep their shield models (:meth:`Run.keep_model`). Returns
    the number of episodes appended."""
    from client.agents.ddpg import DDPGConfig
    from client.agents.ensemble import DDPGEnsemble

    controller, mode = parse_arm(arm)
    if controller != "ddpg":
        raise ValueError(f"lockstep training is for DDPG arms, not {arm!r}")
    if trace and (checkpoint_every is not None or stop is not None):
        raise ValueError("a traced experiment replays from the start: no checkpoints")
    if stop is not None and stop():
        return 0
    if device.startswith("cuda"):  # cuBLAS is deterministic only with a fixed workspace
        os.environ.setdefault("CUBLAS_WORKSPACE_CONFIG", ":4096:8")
    _torch_for_one_core()
    learning = {"lockstep": True, "device": device}
    group = list(range(config.runs) if indices is None else indices)
    saved_at = checkpoint.path_for(out, arm, group)
    identity = {**config.identity(), "arm": arm, "group": group, "learning": learning}
    saved = checkpoint.load(saved_at, identity)
    runs = []
    for i in group if saved is None else saved["active"]:
        model = None if saved is None else saved["places"][i]["model"]
        run = Run.open(config, arm, i, out, token, wrap=False, trace=trace, learning=learning,
                       model=model)
        if run.complete and saved is None:
            run.close()
        else:  # a run of a checkpoint is played on: the members' arithmetic is batched
            runs.append(run)
    if not runs:
        return 0
    shield = Lockstep(runs, config, arm, shadow=mode == "shadow") if mode else None
    learner = DDPGEnsemble(DDPGConfig(**config.ddpg), [r.seed for r in runs], device)
    if saved is None:
        places = [Place.start(r) for r in runs]
        for member in learner.members:
            member.noise.reset()
    else:
        places = [Place.restore(r, saved["places"][r.index]) for r in runs]
        learner.restore(saved["learner"])
    active = list(range(len(runs)))

    def save() -> None:
        if shield:
            shield.send_closing()
        checkpoint.save(saved_at, identity, {
            "active": [runs[k].index for k in active], "learner": learner.state(),
            "places": {runs[k].index: places[k].state(runs[k]) for k in active}})

    next_save = time.monotonic() + (checkpoint_every or 0.0)
    proposals = [0.0] * len(runs)
    try:
        while active:  # learner member j is run active[j]
            for k, a in zip(active, learner.act(np.stack([places[k].obs for k in active])),
                            strict=True):
                proposals[k] = a
            decisions = shield.decide(active, [p.z for p in places], proposals) \
                if shield else [None] * len(active)
            going = list(active)
            for j, (k, decision) in enumerate(zip(list(active), decisions, strict=True)):
                place = places[k]
                action = proposals[k] if decision is None else float(decision.action)
                next_obs, reward, terminated, truncated, info = runs[k].env.step(
                    np.array([action], np.float32))
                if decision is not None:
                    info["shield"], info["shield_observation"] = decision, place.z
                recorder = runs[k].recorder(place.episode)
                if recorder is not None:
                    recorder(proposals[k], info)
                executed = place.meter.add(proposals[k], reward, info)
                learner.members[j].remember(place.obs, executed, reward, next_obs, terminated)
                place.obs, place.z = next_obs, info["efsm_observation"]
                if terminated or truncated:
                    finish = _finisher(runs[k], place.episode, place.meter, info,
                                       place.started, progress)
                    if shield:  # the record waits for the closing decision's state count
                        shield.close_episode(k, place.z, info["event"], finish)
                    else:
                        finish(None)
                    place.episode += 1
                    if place.episode > config.episodes:
                        going.remove(k)
                        continue
                    place.obs, reset_info = runs[k].env.reset()
                    place.z = reset_info["efsm_observation"]
                    place.meter, place.started = EpisodeMeter(), time.perf_counter()
                    learner.members[j].noise.reset()
            learner.update()
            if len(going) < len(active):  # finished runs learn no more: drop their learners
                if going:
                    learner.keep([active.index(k) for k in going])
                active = going
            if active and checkpoint_every is not None and time.monotonic() >= next_save:
                save()
                next_save = time.monotonic() + checkpoint_every
            if active and stop is not None and stop():
                save()
                break
        if shield:
            shield.flush()
            for r in runs:
                r.keep_model()
        if not active:
            checkpoint.remove(saved_at)
    finally:
        for r in runs:
            r.close()
    return sum(r.appended for r in runs)


def _finisher(run: Run, episode: int, meter: EpisodeMeter, info: dict[str, Any], start: float,
              progress: Any | None) -> Callable[[Any], None]:
    wall = time.perf_counter() - start

    def finish(closing: Any) -> None:
        if closing is not None:
            info["shield_done"] = closing
        run.finish(episode, meter.result(info), wall, progress)

    return finish


class Lockstep:
    """The shields of lockstep runs, one round per step: the pending episode ends first, then a
    step of every active run (each model sees its steps in order). Over the batch transport
    the round is one request per service, all in flight at once; over WebSocket every run's
    frame is sent before any reply is read; otherwise each run's own shield is asked in
    turn."""

    def __init__(self, runs: list[Run], config: ExperimentConfig, arm: str,
                 shadow: bool) -> None:
        self.runs = runs
        self.shadow = shadow
        self.names = [model_name(config, arm, r.index) for r in runs]
        # the batch transport: run k's requests go to service_of[k] with the shield of the
        # first run there (one request per service and round)
        batch = [r.shield for r in runs if isinstance(r.shield, BatchShield)]
        self.service_of = [config.shield_url(r.index) for r in runs] \
            if len(batch) == len(runs) else []
        self.carriers: dict[str, BatchShield] = {}
        for url, shield in zip(self.service_of, batch, strict=False):
            self.carriers.setdefault(url, shield)
        self.pool = ThreadPoolExecutor(len(self.carriers)) if len(self.carriers) > 1 else None
        self.closing: list[tuple[int, dict[str, Any], Callable[[Any], None]]] = []

    def close_episode(self, k: int, z: Any, event: str | None,
                      finish: Callable[[Any], None]) -> None:
        """Queue run k's episode end for the next round."""
        body = step_body(z, None, done=True, event=event, shadow=self.shadow)
        self.closing.append((k, body, finish))

    def decide(self, active: list[int], z: list[Any], proposals: list[float]) -> list[Any]:
        """Send the queued episode ends, then one step of every active run."""
        requests = [(k, body) for k, body, _ in self.closing] + [
            (k, step_body(z[k], proposals[k], shadow=self.shadow)) for k in active]
        decisions = self._send(requests)
        for (_, _, finish), closing in zip(self.closing, decisions, strict=False):
            finish(closing)
        answered = decisions[len(self.closing):]
        self.closing = []
        return answered

    def send_closing(self) -> None:
        """Send the queued episode ends now: each model still sees its own steps in order."""
        if self.closing:
            self.decide([], [], [])

    def flush(self) -> None:
        """Send the episode ends still queued when the runs are over, and let the threads of
        the batch requests go."""
        self.send_closing()
        if self.pool is not None:
            self.pool.shutdown()

    def _send(self, requests: list[tuple[int, dict[str, Any]]]) -> list[Any]:
        if self.carriers:
            return self._send_batches(requests)
        sessions = [self.runs[k].shield for k, _ in requests]
        if all(isinstance(s, ShieldSession) for s in sessions):
            return ShieldSession.revise_across(
                [(s, body) for s, (_, body) in zip(sessions, requests, strict=True)])  # type: ignore[misc]
        out = []
        for k, body in requests:
            shield = self.runs[k].shield
            assert shield is not None
            options = {key: v for key, v in body.items() if key not in ("observation", "action")}
            out.append(shield.revise(body["observation"], body["action"], **options))
        return out

    def _send_batches(self, requests: list[tuple[int, dict[str, Any]]]) -> list[Any]:
        """One batch request per service; the decisions back in the order of ``requests``."""
        rounds: dict[str, list[tuple[str, dict[str, Any]]]] = {}
        for k, body in requests:
            rounds.setdefault(self.service_of[k], []).append((self.names[k], body))
        if self.pool is None:
            answers = [self.carriers[url].revise_many(steps) for url, steps in rounds.items()]
        else:
            answers = BatchShield.revise_across(
                [(self.carriers[url], steps) for url, steps in rounds.items()], self.pool)
        decisions = {url: iter(a) for url, a in zip(rounds, answers, strict=True)}
        return [next(decisions[self.service_of[k]]) for k, _ in requests]


def die_with_parent(parent: int) -> None:
    """A worker (or the progress queue's manager, or the demo's shield service) ends with the
    process that started it, even one killed outright: an orphan would go on appending to
    records that a restarted experiment is writing too, or linger."""
    if sys.platform == "linux":
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(PR_SET_PDEATHSIG, signal.SIGTERM)
        if os.getppid() != parent:  # the parent died before the call
            os._exit(1)


def run_all(config: ExperimentConfig, out: Path, workers: int, token: str | None = None,
            bar: Any | None = None, lockstep: int = 0, trace: bool = False,
            device: str = "cpu", checkpoint_every: float | None = None,
            deadline: float | None = None) -> int:
    """Every (arm, run) in its own process, at most ``workers`` at a time. With ``lockstep``
    N > 0 the runs of each DDPG arm go N to a process, each group with one batched update on
    ``device``, saving a checkpoint every ``checkpoint_every`` seconds and stopping (with one)
    at ``deadline`` (seconds since the epoch); other runs stop at the deadline after their
    episode. With ``trace`` shielded runs write step traces."""
    if device != "cpu" and not lockstep:
        raise ValueError(f"learning on {device!r} is for lockstep runs (--lockstep)")
    if checkpoint_every is not None and not lockstep:
        raise ValueError("checkpoints are written by lockstep runs (--lockstep)")
    stop = None if deadline is None else partial(past, deadline)
    jobs: list[tuple[Callable[..., int], tuple[Any, ...]]] = []
    for arm in config.arms:
        if lockstep and parse_arm(arm)[0] == "ddpg":
            for first in range(0, config.runs, lockstep):
                group = list(range(first, min(first + lockstep, config.runs)))
                jobs.append((partial(run_lockstep, indices=group, device=device,
                                     checkpoint_every=checkpoint_every, stop=stop),
                             (config, arm, out, token)))
        else:
            jobs.extend((partial(run_one, stop=stop), (config, arm, run, out, token))
                        for run in range(config.runs))
    context = multiprocessing.get_context("spawn")
    manager = SyncManager(ctx=context)
    manager.start(die_with_parent, (os.getpid(),))
    with manager, ProcessPoolExecutor(
            workers, mp_context=context, initializer=die_with_parent,
            initargs=(os.getpid(),)) as pool:
        progress = manager.Queue()
        pending: set[Future[int]] = {pool.submit(job, *args, progress, trace)
                                     for job, args in jobs}
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
