"""The runs of a DDPG arm stepping together in one process: one batched update of every run's
learner per step (:class:`~client.agents.ensemble.DDPGEnsemble`) and one round of shield
requests per step, with checkpoints to go on from (:mod:`.checkpoint`)."""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from client.experiment import checkpoint
from client.experiment.runner import (
    EpisodeMeter,
    ExperimentConfig,
    Run,
    model_name,
    model_state,
    overlap_pool,
    parse_arm,
    torch_for_one_core,
    while_updating,
)
from client.shield import BatchShield, ShieldSession
from client.shield.remote import step_body


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
        return {
            "episode": self.episode,
            "meter": self.meter,
            "obs": self.obs,
            "z": self.z,
            "elapsed": time.perf_counter() - self.started,
            "env": run.env.state(),
            "model": None
            if run.shield is None
            else model_state(run.config, run.arm, run.index, run.shield, run.token),
        }

    @classmethod
    def restore(cls, run: Run, state: dict[str, Any]) -> Place:
        run.env.restore(state["env"])
        return cls(
            state["episode"],
            state["meter"],
            time.perf_counter() - state["elapsed"],
            state["obs"],
            state["z"],
        )


def run_lockstep(
    config: ExperimentConfig,
    arm: str,
    out: Path,
    token: str | None = None,
    progress: Any | None = None,
    trace: bool = False,
    indices: Sequence[int] | None = None,
    device: str = "cpu",
    checkpoint_every: float | None = None,
    stop: Callable[[], bool] | None = None,
) -> int:
    """The runs of a DDPG arm (all, or those ``indices``) in one process, stepping together: one
    batched DDPG update for all runs per step (:class:`~client.agents.ensemble.DDPGEnsemble`,
    on ``device``), and one round of shield requests per step: with the batch transport one
    request carrying a step of every run's model, over WebSocket every run's step sent before
    any reply is read. Each run sees the same sequence as :func:`run_one` (act, shield, step,
    remember, update; with ``update_first`` the update comes while the shields answer);
    results agree within the rounding of batched arithmetic.

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
    torch_for_one_core()
    learning = {"lockstep": True, "device": device}
    group = list(range(config.runs) if indices is None else indices)
    saved_at = checkpoint.path_for(out, arm, group)
    identity = {**config.identity(), "arm": arm, "group": group, "learning": learning}
    saved = checkpoint.load(saved_at, identity)
    runs = []
    for i in group if saved is None else saved["active"]:
        model = None if saved is None else saved["places"][i]["model"]
        run = Run.open(
            config, arm, i, out, token, wrap=False, trace=trace, learning=learning, model=model
        )
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
    first = learner.config.update_first
    pool = overlap_pool(learner, [r.shield for r in runs])

    def decide(active: list[int], z: list[Any], proposals: list[float]) -> list[Any]:
        return shield.decide(active, z, proposals) if shield else [None] * len(active)

    def save() -> None:
        if shield:
            shield.send_closing()
        checkpoint.save(
            saved_at,
            identity,
            {
                "active": [runs[k].index for k in active],
                "learner": learner.state(),
                "places": {runs[k].index: places[k].state(runs[k]) for k in active},
            },
        )

    next_save = time.monotonic() + (checkpoint_every or 0.0)
    proposals = [0.0] * len(runs)
    try:
        while active:  # learner member j is run active[j]
            for k, a in zip(
                active, learner.act(np.stack([places[k].obs for k in active])), strict=True
            ):
                proposals[k] = a
            observed = [p.z for p in places]
            if first:
                decisions = while_updating(learner, pool, decide, active, observed, proposals)
            else:
                decisions = decide(active, observed, proposals)
            going = list(active)
            for j, (k, decision) in enumerate(zip(list(active), decisions, strict=True)):
                place = places[k]
                action = proposals[k] if decision is None else float(decision.action)
                next_obs, reward, terminated, truncated, info = runs[k].env.step(
                    np.array([action], np.float32)
                )
                if decision is not None:
                    info["shield"], info["shield_observation"] = decision.to_dict(), place.z
                recorder = runs[k].recorder(place.episode)
                if recorder is not None:
                    recorder(proposals[k], info)
                executed = place.meter.add(proposals[k], reward, info)
                learner.members[j].remember(place.obs, executed, reward, next_obs, terminated)
                place.obs, place.z = next_obs, info["efsm_observation"]
                if terminated or truncated:
                    finish = _finisher(
                        runs[k], place.episode, place.meter, info, place.started, progress
                    )
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
            if not first:
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
        if pool is not None:
            pool.shutdown()
        for r in runs:
            r.close()
    return sum(r.appended for r in runs)


def _finisher(
    run: Run,
    episode: int,
    meter: EpisodeMeter,
    info: dict[str, Any],
    start: float,
    progress: Any | None,
) -> Callable[[Any], None]:
    wall = time.perf_counter() - start

    def finish(closing: Any) -> None:
        if closing is not None:
            info["shield_done"] = closing.to_dict()
        run.finish(episode, meter.result(info), wall, progress)

    return finish


class Lockstep:
    """The shields of lockstep runs, one round per step: the pending episode ends first, then a
    step of every active run (each model sees its steps in order). Over the batch transport
    the round is one request per service, all in flight at once; over WebSocket every run's
    frame is sent before any reply is read; otherwise each run's own shield is asked in
    turn."""

    def __init__(self, runs: list[Run], config: ExperimentConfig, arm: str, shadow: bool) -> None:
        self.runs = runs
        self.shadow = shadow
        self.names = [model_name(config, arm, r.index) for r in runs]
        # the batch transport: run k's requests go to service_of[k] with the shield of the
        # first run there (one request per service and round)
        batch = [r.shield for r in runs if isinstance(r.shield, BatchShield)]
        self.service_of = (
            [config.shield_url(r.index) for r in runs] if len(batch) == len(runs) else []
        )
        self.carriers: dict[str, BatchShield] = {}
        for url, shield in zip(self.service_of, batch, strict=False):
            self.carriers.setdefault(url, shield)
        self.pool = ThreadPoolExecutor(len(self.carriers)) if len(self.carriers) > 1 else None
        self.closing: list[tuple[int, dict[str, Any], Callable[[Any], None]]] = []

    def close_episode(
        self, k: int, z: Any, event: str | None, finish: Callable[[Any], None]
    ) -> None:
        """Queue run k's episode end for the next round."""
        body = step_body(z, None, done=True, event=event, shadow=self.shadow)
        self.closing.append((k, body, finish))

    def decide(self, active: list[int], z: list[Any], proposals: list[float]) -> list[Any]:
        """Send the queued episode ends, then one step of every active run."""
        requests = [(k, body) for k, body, _ in self.closing] + [
            (k, step_body(z[k], proposals[k], shadow=self.shadow)) for k in active
        ]
        decisions = self._send(requests)
        for (_, _, finish), closing in zip(self.closing, decisions, strict=False):
            finish(closing)
        answered = decisions[len(self.closing) :]
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
                [(s, body) for s, (_, body) in zip(sessions, requests, strict=True)]  # type: ignore[misc]
            )
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
                [(self.carriers[url], steps) for url, steps in rounds.items()], self.pool
            )
        decisions = {url: iter(a) for url, a in zip(rounds, answers, strict=True)}
        return [next(decisions[self.service_of[k]]) for k, _ in requests]
