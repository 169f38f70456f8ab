"""Lockstep groups stopped (on purpose or by a crash) go on from their checkpoint and record
exactly what an uninterrupted group records."""

from __future__ import annotations

import dataclasses
import gzip
import json
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import torch

from app.core import Shield
from app.service import codec
from client.agents.ddpg import DDPGConfig
from client.agents.ensemble import DDPGEnsemble
from client.experiment import checkpoint, records, runner
from client.experiment.lockstep import run_lockstep
from client.experiment.records import EpisodeRecord, RecordError
from client.sim.car_following import CarFollowingEnv
from client.sim.lead import synthetic

ARM = "ddpg+shield"
CONFIG = runner.ExperimentConfig(
    arms=(ARM,),
    runs=3,
    episodes=5,
    seed=7,
    lead="synthetic",
    ddpg={"warmup": 64, "buffer_size": 5000},
    shield_config={"reviser": {"activate_after_episodes": 2}},
)


IDENTITY = {
    **CONFIG.identity(),
    "arm": ARM,
    "group": [0, 1, 2],
    "learning": {"lockstep": True, "device": "cpu"},
}


def recorded(directory: Path, config: runner.ExperimentConfig = CONFIG) -> list[EpisodeRecord]:
    """Every run's episodes, the wall time left out."""
    return [
        dataclasses.replace(r, wall_s=0.0)
        for run in range(config.runs)
        for r in records.read(records.path_for(directory, ARM, run))[1]
    ]


def after(steps: int) -> Callable[[], bool]:
    """A stop that says yes after ``steps`` steps."""
    count = iter(range(steps))
    return lambda: next(count, None) is None


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory: pytest.TempPathFactory) -> list[EpisodeRecord]:
    out = tmp_path_factory.mktemp("whole")
    assert run_lockstep(CONFIG, ARM, out) == CONFIG.runs * CONFIG.episodes
    assert not checkpoint.pending(out)
    return recorded(out)


def test_the_simulator_goes_on_exactly_from_its_state() -> None:
    lead = synthetic(0, count=4)
    env, copy = CarFollowingEnv(lead=lead), CarFollowingEnv(lead=lead)
    env.reset(seed=3)
    for _ in range(40):
        env.step(np.array([0.3], np.float32))
    copy.restore(env.state())
    for env_ in (env, copy):  # the rest of the episode and the start of the next one
        env_.trail = [env_.step(np.array([-0.2], np.float32))[0] for _ in range(30)]  # type: ignore[attr-defined]
        env_.trail.append(env_.reset()[0])  # type: ignore[attr-defined]
    np.testing.assert_array_equal(env.trail, copy.trail)  # type: ignore[attr-defined]


def test_an_ensemble_goes_on_exactly_from_its_state() -> None:
    config = DDPGConfig(warmup=64, buffer_size=500)
    rng = np.random.default_rng(0)
    obs = rng.uniform(0, 30, (600, 2, 4)).astype(np.float32)

    def train(ensemble: DDPGEnsemble, steps: range) -> list[list[float]]:
        actions = []
        for t in steps:  # past the buffer's size, so that the ring has wrapped
            actions.append(ensemble.act(obs[t]))
            for k, member in enumerate(ensemble.members):
                member.remember(obs[t, k], actions[-1][k], -1.0, obs[t + 1, k], False)
            ensemble.update()
        return actions

    whole = DDPGEnsemble(config, [1, 2])
    train(whole, range(550))
    state = whole.state()
    rest = train(whole, range(550, 599))
    other = DDPGEnsemble(config, [1, 2])
    other.restore(state)
    assert train(other, range(550, 599)) == rest
    with pytest.raises(ValueError, match="members"):
        DDPGEnsemble(config, [1]).restore(state)


@pytest.mark.parametrize("every", [97, 300])
def test_a_group_stopped_again_and_again_records_what_an_uninterrupted_one_records(
    tmp_path: Path, every: int, uninterrupted: list[EpisodeRecord]
) -> None:
    """Stops mid-episode, between a run's last episode and the others', and after runs are
    done: each stop leaves a checkpoint, each call goes on from it, and the records come out
    identical to the bit."""
    stops = 0
    run_lockstep(CONFIG, ARM, tmp_path, stop=after(every))
    while checkpoint.pending(tmp_path):
        stops += 1
        run_lockstep(CONFIG, ARM, tmp_path, stop=after(every))
    assert stops >= 2
    assert recorded(tmp_path) == uninterrupted


def test_a_crashed_group_goes_on_from_its_last_checkpoint(
    tmp_path: Path, uninterrupted: list[EpisodeRecord]
) -> None:
    """Episodes recorded after the last checkpoint are played again and checked (the run
    has 974 steps)."""

    class Crash(Exception):
        pass

    def crash_after(steps: int) -> Callable[[], bool]:
        stop = after(steps)

        def check() -> bool:
            if stop():
                raise Crash
            return False

        return check

    with pytest.raises(Crash):
        run_lockstep(CONFIG, ARM, tmp_path, checkpoint_every=0.3, stop=crash_after(800))
    saved = checkpoint.load(checkpoint.pending(tmp_path)[0], IDENTITY)
    assert saved is not None
    before = len(recorded(tmp_path))
    assert run_lockstep(CONFIG, ARM, tmp_path) == len(uninterrupted) - before
    assert recorded(tmp_path) == uninterrupted
    assert not checkpoint.pending(tmp_path)  # done: removed


def test_a_stopped_group_keeps_the_models_of_its_checkpoint(tmp_path: Path) -> None:
    """OUT/models holds each run's model where the group stopped: the checkpoint's, in the
    form PUT /models/{name} takes."""
    run_lockstep(CONFIG, ARM, tmp_path, stop=after(300))
    saved = checkpoint.load(checkpoint.pending(tmp_path)[0], IDENTITY)
    assert saved is not None
    for run in range(CONFIG.runs):
        kept = json.loads(
            gzip.decompress(
                (tmp_path / "models" / f"ddpg_shield__run{run:02d}.json.gz").read_bytes()
            )
        )
        assert kept == {"exact": json.loads(json.dumps(saved["places"][run]["model"]))}
        assert Shield.from_snapshot(codec.from_json(kept["exact"])).n_states > 0


def test_a_checkpoint_of_another_experiment_is_refused(tmp_path: Path) -> None:
    run_lockstep(CONFIG, ARM, tmp_path, stop=after(50))
    other = dataclasses.replace(CONFIG, seed=8)
    with pytest.raises(RecordError, match="another experiment"):
        run_lockstep(other, ARM, tmp_path)


def test_a_checkpoint_of_another_format_is_refused(tmp_path: Path) -> None:
    """A checkpoint written by a client whose learner saved its state another way (format 1:
    per-layer weights and an optimizer's state) is refused with what to do, not misread."""
    run_lockstep(CONFIG, ARM, tmp_path, stop=after(50))
    saved_at = checkpoint.pending(tmp_path)[0]
    saved = torch.load(saved_at, weights_only=False)
    torch.save({**saved, "format": 1}, saved_at)
    with pytest.raises(RecordError, match="format 1, written by another version"):
        run_lockstep(CONFIG, ARM, tmp_path)


def test_a_group_goes_on_against_a_fresh_service(
    tmp_path: Path, uninterrupted: list[EpisodeRecord]
) -> None:
    """The service that held the models is gone when the group goes on (a new machine, a
    new session): the models come back from the checkpoint."""
    from tests.conftest import start_server

    for stops in (1, 2):
        server = start_server(tmp_path / f"data-{stops}", "--fsync", "never")
        remote = dataclasses.replace(CONFIG, shield=server.url, transport="batch")
        try:
            run_lockstep(remote, ARM, tmp_path / "out", stop=after(400) if stops == 1 else None)
        finally:
            server.stop()
    assert recorded(tmp_path / "out") == uninterrupted


def test_the_command_stops_at_its_deadline_and_goes_on(tmp_path: Path) -> None:
    command = [
        sys.executable,
        "-m",
        "client",
        "run",
        "--arms",
        ARM,
        "--runs",
        "2",
        "--episodes",
        "40",
        "--seed",
        "7",
        "--lead",
        "synthetic",
        "--lockstep",
        "--workers",
        "1",
        "--out",
        str(tmp_path),
    ]
    other = records.path_for(tmp_path, "idm", 0)  # another arm, finished: not counted
    records.start(other, {"identity": "an arm run before"}, 100)
    for episode in range(1, 101):
        records.append(
            other,
            EpisodeRecord(
                arm="idm",
                run=0,
                episode=episode,
                seed=1,
                steps=800,
                outcome="success",
                interventions={},
                revisions_would=0,
                speed_diff_n=800,
                speed_diff_mean=0.1,
                speed_diff_var=0.1,
                episode_return=-1.0,
                n_states=0,
                wall_s=0.1,
            ),
        )
    first = subprocess.run(
        [*command, "--stop-after", "0.06"], capture_output=True, text=True, timeout=600
    )
    assert first.returncode == 0, first.stderr
    assert "stopped at the deadline with" in first.stdout
    assert not (tmp_path / "table.md").exists()
    then = subprocess.run(command, capture_output=True, text=True, timeout=600)
    assert then.returncode == 0, then.stderr
    assert (tmp_path / "table.md").exists() and not checkpoint.pending(tmp_path)
    refused = subprocess.run(
        [*command, "--stop-after", "1", "--trace"], capture_output=True, text=True
    )
    assert refused.returncode == 2 and "--trace" in refused.stderr
