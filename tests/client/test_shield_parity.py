"""One seed, four transports, the same decisions and the same episodes."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any, Literal

import numpy as np
import pytest

from app.core import ShieldConfig
from client.agents.idm import PRESETS
from client.shield import BatchShield, LocalShield, ShieldClient, ShieldSession, StepShield
from client.shield.wrapper import ShieldWrapper
from client.sim import lead
from client.sim.car_following import CarFollowingEnv
from tests.conftest import Server, start_server

CONFIG: dict[str, Any] = {"reviser": {"activate_after_episodes": 3, "seed": 11}}


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Server]:
    s = start_server(tmp_path_factory.mktemp("parity") / "data", "--fsync", "never")
    yield s
    s.stop()


def episodes(shield: StepShield, count: int = 10) -> list[tuple[Any, ...]]:
    env = ShieldWrapper(
        CarFollowingEnv(lead=lead.synthetic(2, hard_braking=True)), shield, stream="car-1"
    )
    controller = PRESETS["aggressive"]
    records: list[tuple[Any, ...]] = []
    obs, _ = env.reset(seed=5)
    for _ in range(count):
        for _ in range(800):
            obs, reward, terminated, truncated, info = env.step(
                np.array([controller.act(obs)], np.float32)
            )
            records.append((info["shield"], obs.tolist(), reward))
            if terminated or truncated:
                records.append((info["shield_done"], info["event"]))
                break
        obs, _ = env.reset()
    return records


def transports(server: Server, name: str) -> dict[str, StepShield]:
    with ShieldClient(server.url) as admin:
        for transport in ("http", "ws", "batch"):
            admin.create_model(f"{name}-{transport}", CONFIG)
    return {
        "local": LocalShield(ShieldConfig.from_dict(CONFIG)),
        "http": ShieldClient(server.url, model=f"{name}-http"),
        "ws": ShieldSession(server.url, model=f"{name}-ws"),
        "batch": BatchShield(server.url, model=f"{name}-batch"),
    }


def test_all_transports_give_identical_decisions_and_episodes(server: Server) -> None:
    shields = transports(server, "parity")
    runs = {}
    for transport, shield in shields.items():
        runs[transport] = episodes(shield)
        shield.close()
    assert runs["local"] == runs["http"] == runs["ws"] == runs["batch"]
    reasons = {record[0]["reason"] for record in runs["local"]}
    assert "revised_safety" in reasons  # the comparison covers revisions, not only passes


def test_the_wrapper_reports_and_applies_the_decision() -> None:
    shield = LocalShield(ShieldConfig.from_dict(CONFIG))
    records = episodes(shield, count=10)
    revised = [r[0] for r in records if len(r) == 3 and r[0]["revised"]]
    assert revised and all(d["action"] == d["suggested"] for d in revised)
    assert any(d["action"] != d["proposed"] for d in revised)  # (a clipped one may coincide)
    done = [r for r in records if len(r) == 2]
    assert len(done) == 10 and all(r[0]["reason"] == "done" for r in done)
    assert shield.shield.counters.episodes == 10


@pytest.mark.parametrize("transport", ["http", "ws", "batch"])
def test_runner_records_are_identical_in_process_and_over_the_network(
    server: Server,
    transport: Literal["http", "ws", "batch"],
    tmp_path_factory: pytest.TempPathFactory,
) -> None:
    import dataclasses

    from client.experiment import records, runner

    config = runner.ExperimentConfig(
        arms=("idm-aggressive+shield",),
        runs=1,
        episodes=5,
        seed=21,
        lead="synthetic",
        shield_config={"reviser": {"activate_after_episodes": 1}},
        model_prefix=f"runner-{transport}",
    )
    local_dir, remote_dir = tmp_path_factory.mktemp("local"), tmp_path_factory.mktemp("remote")
    runner.run_one(config, config.arms[0], 0, local_dir)
    remote = dataclasses.replace(config, shield=server.url, transport=transport)
    runner.run_one(remote, config.arms[0], 0, remote_dir)

    def episodes(directory: Path) -> list[records.EpisodeRecord]:
        return [
            dataclasses.replace(r, wall_s=0.0)
            for r in records.read(records.path_for(directory, config.arms[0], 0))[1]
        ]

    assert episodes(local_dir) == episodes(remote_dir)
    assert sum(sum(r.interventions.values()) for r in episodes(local_dir)) > 0


def test_ddpg_that_updates_first_records_the_same_in_process_and_over_the_network(
    server: Server, tmp_path_factory: pytest.TempPathFactory
) -> None:
    """With ``update_first`` the learner updates while a remote shield answers (in a second
    thread), and learns what it learns in process: the records agree over every transport,
    and they are not those of the usual order (the option changes the learning)."""
    import dataclasses

    from client.experiment import records, runner

    config = runner.ExperimentConfig(
        arms=("ddpg+shield",),
        runs=1,
        episodes=3,
        seed=23,
        lead="synthetic",
        ddpg={"warmup": 64, "update_first": True},
        shield_config={"reviser": {"activate_after_episodes": 1}},
        model_prefix="first",
    )

    def episodes(config: runner.ExperimentConfig) -> list[records.EpisodeRecord]:
        out = tmp_path_factory.mktemp(config.transport)
        runner.run_one(config, config.arms[0], 0, out)
        return [
            dataclasses.replace(r, wall_s=0.0)
            for r in records.read(records.path_for(out, config.arms[0], 0))[1]
        ]

    local = episodes(config)
    for transport in ("http", "ws", "batch"):
        remote = dataclasses.replace(config, shield=server.url, transport=transport)
        assert episodes(remote) == local, transport
    assert sum(sum(r.interventions.values()) for r in local) > 0
    usual = episodes(dataclasses.replace(config, ddpg={"warmup": 64}))
    assert [r.episode_return for r in usual] != [r.episode_return for r in local]


def test_runs_spread_over_sidecars_keep_their_records(
    server: Server, tmp_path_factory: pytest.TempPathFactory
) -> None:
    """With one URL per run, run i's model lives on the i-th service alone, and the records
    are those of the in-process shield."""
    import dataclasses

    from client.experiment import records, runner

    config = runner.ExperimentConfig(
        arms=("idm-aggressive+shield",),
        runs=2,
        episodes=3,
        seed=22,
        lead="synthetic",
        shield_config={"reviser": {"activate_after_episodes": 1}},
        model_prefix="sidecar",
    )
    sidecar = start_server(tmp_path_factory.mktemp("sidecar") / "data", "--fsync", "never")
    try:
        remote = dataclasses.replace(config, shield=f"{server.url}, {sidecar.url}")
        local_dir, remote_dir = tmp_path_factory.mktemp("local"), tmp_path_factory.mktemp("sc")
        for run in (0, 1):
            runner.run_one(config, config.arms[0], run, local_dir)
            runner.run_one(remote, config.arms[0], run, remote_dir)
        for url, mine, other in ((server.url, 0, 1), (sidecar.url, 1, 0)):
            with ShieldClient(url) as admin:
                names = {m["name"] for m in admin.models()}
            assert runner.model_name(config, config.arms[0], mine) in names
            assert runner.model_name(config, config.arms[0], other) not in names
    finally:
        sidecar.stop()

    for run in (0, 1):
        local, remote_records = (
            [
                dataclasses.replace(r, wall_s=0.0)
                for r in records.read(records.path_for(d, config.arms[0], run))[1]
            ]
            for d in (local_dir, remote_dir)
        )
        assert local == remote_records


def test_a_local_shield_is_not_mixed_with_urls() -> None:
    from client.experiment import runner

    with pytest.raises(ValueError, match="not both"):
        runner.ExperimentConfig(shield="local,http://127.0.0.1:8000")


def test_lockstep_over_the_batch_route_across_services(
    server: Server, tmp_path_factory: pytest.TempPathFactory
) -> None:
    """Lockstep runs spread over two services: each round is one batch request per service,
    both in flight at once; every model lives on its own service only, and the records are
    those of lockstep with in-process shields."""
    import dataclasses

    from client.experiment import records, runner
    from client.experiment.lockstep import run_lockstep

    sidecar = start_server(tmp_path_factory.mktemp("lockstep") / "data", "--fsync", "never")
    try:
        config = runner.ExperimentConfig(
            arms=("ddpg+shield",),
            runs=3,
            episodes=2,
            seed=23,
            lead="synthetic",
            # the paper's reviser acts from the second episode, failures or not
            shield_config={"reviser": {"method": "paper", "activate_after_episodes": 1}},
            model_prefix="lockstep-sidecar",
        )
        remote = dataclasses.replace(
            config, shield=f"{server.url},{sidecar.url}", transport="batch"
        )
        local_dir = tmp_path_factory.mktemp("lockstep-local")
        remote_dir = tmp_path_factory.mktemp("lockstep-remote")
        run_lockstep(config, config.arms[0], local_dir)
        assert run_lockstep(remote, config.arms[0], remote_dir) == 6
        for url, mine in ((server.url, (0, 2)), (sidecar.url, (1,))):
            with ShieldClient(url) as admin:
                held = {m["name"] for m in admin.models()}
                for run in range(3):
                    name = runner.model_name(config, config.arms[0], run)
                    assert (name in held) == (run in mine)
                    if run in mine:
                        assert admin.snapshot(name, tpm="none")["episodes"] == 2
    finally:
        sidecar.stop()
    for run in range(3):
        local, remote_records = (
            [
                dataclasses.replace(r, wall_s=0.0)
                for r in records.read(records.path_for(d, config.arms[0], run))[1]
            ]
            for d in (local_dir, remote_dir)
        )
        assert local == remote_records
    assert any(
        r.interventions for r in records.read(records.path_for(remote_dir, config.arms[0], 0))[1]
    )  # the shield acted
