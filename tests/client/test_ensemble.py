"""Lockstep training of several runs equals training them one by one, within rounding."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from pathlib import Path
from typing import Literal

import numpy as np
import pytest
import torch

from bench.rounding_drift import CONFIG as CONFIG_DRIFT
from bench.rounding_drift import SEEDS, train_side_by_side
from client.agents.ddpg import A_MAX, DDPG, DDPGConfig
from client.agents.ensemble import DDPGEnsemble, Params, _forward
from client.agents.flat import views
from client.experiment import parallel, records, runner
from client.experiment.lockstep import run_lockstep

# Batched products may round differently from single ones, and learning amplifies any such
# difference (bench/rounding_drift.py, whose training loop this test runs). On the CPU, where
# most operations round alike, actions still agree to about 1e-5 m/s^2 after 300 steps
# (measured: 6e-6). On CUDA almost every operation rounds differently: on an H200 (torch
# 2.11) actions parted by 1.1e-5 within the first 100 steps and first by more than 1e-4 at
# step 122, so the CUDA case compares the first 100 steps (37 updates, 34 of them graph
# replays).
ACTION_TOLERANCE = 1e-4
STEPS = {"cpu": 300, "cuda": 100}


DEVICES = [
    "cpu",
    pytest.param(
        "cuda",
        marks=pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device here"),
    ),
]


@pytest.mark.parametrize("device", DEVICES)
def test_ensemble_members_learn_like_separate_runs(device: str) -> None:
    """On CUDA the update is a captured graph after a few eager ones: the replays must go on
    learning what the separate runs learn, within rounding."""
    torch.set_num_threads(1)
    ensemble = DDPGEnsemble(CONFIG_DRIFT, SEEDS, device)
    single = [DDPG(CONFIG_DRIFT, s) for s in SEEDS]
    worst, obs = train_side_by_side(ensemble, single, STEPS[device])
    assert max(worst) <= ACTION_TOLERANCE
    if device == "cuda":
        assert ensemble._graph is not None  # the replays were tested, not eager updates
    greedy = ensemble.act(obs, explore=False)
    np.testing.assert_allclose(
        greedy,
        [a.act(o, explore=False) for a, o in zip(single, obs, strict=True)],
        atol=ACTION_TOLERANCE,
    )


class AutogradUpdate:
    """The ensemble's update as autograd and ``torch.optim.Adam`` compute it, on copies of its
    stacked layers: the form the ensemble's hand-written update replaced."""

    def __init__(self, ensemble: DDPGEnsemble) -> None:
        def copy(params: Params, grad: bool) -> Params:
            return [p.detach().clone().requires_grad_(grad) for p in params]

        self.config = ensemble.config
        self.actor, self.critic = copy(ensemble.actor, True), copy(ensemble.critic, True)
        self.targets = copy([*ensemble.actor_target, *ensemble.critic_target], False)
        self.actor_opt = torch.optim.Adam(self.actor, lr=self.config.actor_lr, foreach=True)
        self.critic_opt = torch.optim.Adam(self.critic, lr=self.config.critic_lr, foreach=True)

    def q(self, critic: Params, obs: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        return _forward(critic, torch.cat([obs, action / A_MAX], dim=2))[2]

    def mu(self, actor: Params, obs: torch.Tensor) -> torch.Tensor:
        return torch.tanh(_forward(actor, obs)[2]) * A_MAX

    def update(self, batch: torch.Tensor) -> None:
        obs, action, reward = batch[..., 0:4], batch[..., 4:5], batch[..., 5:6]
        next_obs, done = batch[..., 6:10], batch[..., 10:11]
        with torch.no_grad():
            layers = len(self.actor)
            next_q = self.q(
                self.targets[layers:], next_obs, self.mu(self.targets[:layers], next_obs)
            )
            target = reward + self.config.gamma * (1.0 - done) * next_q
        critic_loss = ((self.q(self.critic, obs, action) - target) ** 2).mean(dim=(1, 2)).sum()
        self.critic_opt.zero_grad()
        critic_loss.backward()  # type: ignore[no-untyped-call]
        self.critic_opt.step()
        for p in self.critic:
            p.requires_grad_(False)
        actor_loss = -self.q(self.critic, obs, self.mu(self.actor, obs)).mean(dim=(1, 2)).sum()
        self.actor_opt.zero_grad()
        actor_loss.backward()  # type: ignore[no-untyped-call]
        self.actor_opt.step()
        for p in self.critic:
            p.requires_grad_(True)
        with torch.no_grad():
            torch._foreach_lerp_(self.targets, [*self.actor, *self.critic], self.config.tau)

    def moments(self, name: str) -> torch.Tensor:
        """One of Adam's moments of every layer, laid out as the ensemble's flat buffers."""
        return torch.cat(
            [
                opt.state[p][name].reshape(-1)
                for opt, params in ((self.actor_opt, self.actor), (self.critic_opt, self.critic))
                for p in params
            ]
        )


def assert_moments_are_adams(
    moments: torch.Tensor, reference: Callable[[str], torch.Tensor]
) -> None:
    """Adam's first and second moments (the rows of ``moments``) equal ``torch.optim.Adam``'s
    (``reference("exp_avg")``, ``reference("exp_avg_sq")``) but for the subnormal ones, which
    the learners flush to zero where the CPU can; such moments, and dead units, must occur,
    so that the flushing was put to the test."""
    tiny = torch.finfo(torch.float32).tiny
    flushes = torch.set_flush_denormal(True)  # whether this CPU can
    torch.set_flush_denormal(False)
    for row, name in zip(moments, ("exp_avg", "exp_avg_sq"), strict=True):
        exact = reference(name)
        subnormal = (exact != 0) & (exact.abs() < tiny)
        assert torch.equal(row, torch.where(subnormal, 0.0, exact) if flushes else exact)
        if name == "exp_avg":
            assert subnormal.any()
        else:
            assert (exact == 0).any()  # dead units


def test_the_update_is_autograds_and_adams_bit_for_bit() -> None:
    """Gradients by hand and Adam over flat buffers: the same operations as autograd's
    backward pass and ``torch.optim.Adam``, so weights and targets agree with theirs exactly,
    update after update, long enough for ReLU units to die and their Adam moments to decay
    into subnormal numbers; the ensemble flushes those to zero (where the CPU can), and
    nothing else differs."""
    torch.set_num_threads(1)
    ensemble = DDPGEnsemble(DDPGConfig(warmup=64), [4, 5, 6])
    rng = np.random.default_rng(0)
    for member in ensemble.members:
        for _ in range(500):
            member.remember(
                rng.uniform(0, 30, 4).astype(np.float32),
                rng.uniform(-2, 2),
                rng.uniform(-3, 0),
                rng.uniform(0, 30, 4).astype(np.float32),
                rng.random() < 0.05,
            )
    reference = AutogradUpdate(ensemble)
    for _ in range(1000):
        ensemble.update()
        reference.update(ensemble._batch)  # the batch the ensemble drew
    state = ensemble.state()
    assert torch.equal(
        state["online"],
        torch.cat([p.detach().reshape(-1) for p in [*reference.actor, *reference.critic]]),
    )
    assert torch.equal(state["target"], torch.cat([p.reshape(-1) for p in reference.targets]))
    assert state["steps"].tolist() == [1000.0, 1000.0]
    assert_moments_are_adams(state["moments"], reference.moments)


def test_a_batch_drawn_into_rows_is_the_batch_a_run_draws() -> None:
    """The ensemble's draw (whole rows of the memory, one gather) takes the transitions a
    separate run's draw takes, each field in its column, and leaves the generator where
    that draw leaves it."""
    separate, batched = DDPG(DDPGConfig(), 3).buffer, DDPG(DDPGConfig(), 3).buffer
    rng = np.random.default_rng(1)
    for _ in range(300):
        obs, next_obs = rng.uniform(0, 1, 4).astype(np.float32), rng.uniform(0, 1, 4)
        action, reward, terminal = rng.uniform(-2, 2), rng.uniform(-3, 0), rng.random() < 0.1
        for memory in (separate, batched):
            memory.add(obs, action, reward, next_obs.astype(np.float32), terminal)
    rows = np.full((64, 11), np.nan, np.float32)
    for _ in range(3):
        batch = separate.sample(64)
        batched.sample_into(rows)
        assert np.array_equal(rows, torch.cat(list(batch), dim=1).numpy())
        assert batch.done.sum() > 0


CONFIG = runner.ExperimentConfig(
    arms=("ddpg+shield",),
    runs=3,
    episodes=5,
    seed=7,
    lead="synthetic",
    ddpg={"warmup": 64},
    shield_config={"reviser": {"activate_after_episodes": 2}},
)


def episodes(directory: Path, run: int) -> list[records.EpisodeRecord]:
    return records.read(records.path_for(directory, "ddpg+shield", run))[1]


@pytest.mark.parametrize("update_first", [False, True])
def test_lockstep_runs_record_what_separate_runs_record(tmp_path: Path, update_first: bool) -> None:
    """Batched products round differently (about 1e-7 per action), and the shield's discrete
    choices (a new state or not, a bin edge) can turn that into a different episode once it
    acts. So: the episodes before the reviser switches on agree exactly, and every run's
    record is complete; in either order of update and step."""
    config = dataclasses.replace(CONFIG, ddpg={**CONFIG.ddpg, "update_first": update_first})
    separate, lockstep = tmp_path / "separate", tmp_path / "lockstep"
    for run in range(CONFIG.runs):
        runner.run_one(config, "ddpg+shield", run, separate)
    assert run_lockstep(config, "ddpg+shield", lockstep) == CONFIG.runs * CONFIG.episodes
    before = CONFIG.shield_config["reviser"]["activate_after_episodes"]
    for run in range(CONFIG.runs):
        a, b = episodes(separate, run), episodes(lockstep, run)
        assert [r.episode for r in b] == list(range(1, CONFIG.episodes + 1))
        assert [(r.steps, r.outcome) for r in a[:before]] == [
            (r.steps, r.outcome) for r in b[:before]
        ]
        assert [r.episode_return for r in b[:before]] == pytest.approx(
            [r.episode_return for r in a[:before]], rel=1e-4
        )
    # and a lockstep experiment resumes like any other
    assert run_lockstep(config, "ddpg+shield", lockstep) == 0
    bigger = dataclasses.replace(config, episodes=6)
    with pytest.raises(records.RecordError):
        run_lockstep(bigger, "ddpg+shield", lockstep)  # another configuration


def test_lockstep_is_for_ddpg_arms(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="DDPG arms"):
        run_lockstep(dataclasses.replace(CONFIG, arms=("idm",)), "idm", tmp_path)


@pytest.mark.parametrize(
    ("transport", "update_first"), [("batch", False), ("ws", False), ("batch", True)]
)
def test_lockstep_against_a_service_equals_lockstep_in_process(
    tmp_path: Path, transport: Literal["http", "ws", "batch"], update_first: bool
) -> None:
    """One round per lockstep step (over the batch route one request carrying a step of every
    run's model; over WebSocket every run's frame sent before any reply is read): each model
    still sees its own steps in order and the learner's arithmetic is the in-process one, so
    the records are identical; with ``update_first`` too, where the batched update runs
    while the service answers."""
    from tests.conftest import start_server

    server = start_server(tmp_path / "data", "--fsync", "never")
    try:
        config = dataclasses.replace(CONFIG, ddpg={**CONFIG.ddpg, "update_first": update_first})
        remote = dataclasses.replace(config, shield=server.url, transport=transport)
        local_dir, remote_dir = tmp_path / "local", tmp_path / "remote"
        run_lockstep(config, "ddpg+shield", local_dir)
        run_lockstep(remote, "ddpg+shield", remote_dir)
        for run in range(CONFIG.runs):
            a = [dataclasses.replace(r, wall_s=0.0) for r in episodes(local_dir, run)]
            b = [dataclasses.replace(r, wall_s=0.0) for r in episodes(remote_dir, run)]
            assert a == b
        assert any(r.interventions for r in episodes(remote_dir, 0))  # the shield acted
    finally:
        server.stop()


@pytest.mark.parametrize("device", DEVICES)
def test_dropping_members_leaves_the_others_learning_as_before(device: str) -> None:
    torch.set_num_threads(1)
    config = DDPGConfig(warmup=64)
    full, cut = DDPGEnsemble(config, [1, 2, 3], device), DDPGEnsemble(config, [1, 2, 3], device)
    rng = np.random.default_rng(0)
    obs = rng.uniform(0, 30, (3, 4)).astype(np.float32)
    for t in range(200):
        if t == 120:
            cut.keep([0, 2])  # run 1 is over
            before, kept_state = full.state(), cut.state()  # the same so far, bit for bit

            def rows(flat: torch.Tensor) -> torch.Tensor:
                shapes = [p.shape for p in [*full.actor, *full.critic]]
                return torch.cat([v[[0, 2]].reshape(-1) for v in views(flat, shapes)])

            for name in ("online", "target"):
                assert torch.equal(kept_state[name], rows(before[name]))
            assert torch.equal(
                kept_state["moments"], torch.stack([rows(m) for m in before["moments"]])
            )
            assert kept_state["moments"].abs().sum() > 0  # the Adam moments came along
        kept = [0, 2] if t >= 120 else [0, 1, 2]
        a_full, a_cut = full.act(obs), cut.act(obs[kept])
        np.testing.assert_allclose(np.array(a_full)[kept], a_cut, atol=ACTION_TOLERANCE)
        following = rng.uniform(0, 30, (3, 4)).astype(np.float32)
        reward = rng.uniform(-3, 0, 3)
        for k in range(3):
            full.members[k].remember(obs[k], a_full[k], reward[k], following[k], False)
        for j, k in enumerate(kept):
            cut.members[j].remember(obs[k], a_cut[j], reward[k], following[k], False)
        full.update()
        cut.update()
        obs = following
    assert len(cut.members) == 2


def test_lockstep_groups_record_every_run_and_how_it_learned(tmp_path: Path) -> None:
    """Three runs two to a process: every run is recorded, the groups' runs start as they do
    in one group of three, and each header says the learner ran in lockstep on the CPU."""
    whole, grouped = tmp_path / "whole", tmp_path / "grouped"
    run_lockstep(CONFIG, "ddpg+shield", whole)
    assert parallel.run_all(CONFIG, grouped, workers=2, lockstep=2) == CONFIG.runs * CONFIG.episodes
    before = CONFIG.shield_config["reviser"]["activate_after_episodes"]
    for run in range(CONFIG.runs):
        a, b = episodes(whole, run), episodes(grouped, run)
        assert [(r.steps, r.outcome) for r in a[:before]] == [
            (r.steps, r.outcome) for r in b[:before]
        ]
        assert len(b) == CONFIG.episodes
        header, _ = records.read(records.path_for(grouped, "ddpg+shield", run))
        assert header["learning"] == {"lockstep": True, "device": "cpu"}


def test_learning_on_a_device_is_for_lockstep_runs(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="lockstep"):
        parallel.run_all(CONFIG, tmp_path, workers=1, device="cuda")
