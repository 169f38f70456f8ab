"""Runner, records and report: resumable runs, the paper's numbers, one clear line per error."""

from __future__ import annotations

import dataclasses
import gzip
import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import httpx
import numpy as np
import pytest
import torch

from app.core import Shield
from app.service import codec
from client.agents.ddpg import DDPG, DDPGConfig
from client.experiment import records, report, runner, trace
from client.experiment.records import EpisodeRecord
from client.sim.car_following import RewardConfig
from tests.conftest import free_port

CONFIG = runner.ExperimentConfig(
    arms=("idm-aggressive", "idm-aggressive+shield"),
    runs=1,
    episodes=8,
    seed=3,
    lead="synthetic",
    shield_config={"reviser": {"activate_after_episodes": 2}},
)


def without_wall(rs: list[EpisodeRecord]) -> list[EpisodeRecord]:
    return [dataclasses.replace(r, wall_s=0.0) for r in rs]


def test_an_interrupted_run_resumes_without_losing_or_duplicating(tmp_path: Path) -> None:
    whole, broken = tmp_path / "whole", tmp_path / "broken"
    arm = "idm-aggressive+shield"
    assert runner.run_one(CONFIG, arm, 0, whole) == 8
    runner.run_one(CONFIG, arm, 0, broken)
    path = records.path_for(broken, arm, 0)
    lines = path.read_text().splitlines(keepends=True)
    path.write_text("".join(lines[:4]) + lines[4][:25])  # 3 episodes and a torn fourth
    assert len(records.read(path)[1]) == 3
    assert runner.run_one(CONFIG, arm, 0, broken) == 5
    expected = without_wall(records.read(records.path_for(whole, arm, 0))[1])
    assert without_wall(records.read(path)[1]) == expected
    assert runner.run_one(CONFIG, arm, 0, broken) == 0  # complete: nothing to do


def test_records_from_another_configuration_are_refused(tmp_path: Path) -> None:
    runner.run_one(CONFIG, "idm-aggressive", 0, tmp_path)
    other = dataclasses.replace(CONFIG, seed=4)
    with pytest.raises(records.RecordError, match="another configuration"):
        runner.run_one(other, "idm-aggressive", 0, tmp_path)


def test_records_made_under_other_shield_defaults_are_refused(tmp_path: Path) -> None:
    """The same overrides under changed defaults are another experiment: the header's
    resolved shield configuration tells them apart."""
    arm = "idm-aggressive+shield"
    runner.run_one(CONFIG, arm, 0, tmp_path)
    path = records.path_for(tmp_path, arm, 0)
    lines = path.read_text().splitlines(keepends=True)
    header = json.loads(lines[0])
    header["header"]["shield"]["flag_min_rate_unused"] = None  # a field that no longer exists
    path.write_text(json.dumps(header) + "\n" + "".join(lines[1:]))
    with pytest.raises(records.RecordError, match="another shield configuration"):
        runner.run_one(CONFIG, arm, 0, tmp_path)
    del header["header"]["shield"]["flag_min_rate_unused"]
    header["header"]["shield"]["observation"]["high"] = [32.0, 200.0, 32.0]  # older defaults
    path.write_text(json.dumps(header) + "\n" + "".join(lines[1:]))
    with pytest.raises(records.RecordError, match="another shield configuration"):
        runner.run_one(CONFIG, arm, 0, tmp_path)


def test_records_from_before_a_switch_existed_keep_the_value_it_was_added_with(
    tmp_path: Path,
) -> None:
    """``reviser.one_sided`` was added off and is on by default now: a header of the stored
    format's version 1 that lacks it ran with it off, so only the overrides that turn it off
    again go on with those records."""
    arm = "idm-aggressive+shield"
    off = dataclasses.replace(
        CONFIG,
        shield_config={  # (version 1's risk reviser: removed)
            "reviser": {"method": "paper", "activate_after_episodes": 2, "one_sided": False}
        },
    )
    runner.run_one(off, arm, 0, tmp_path)
    path = records.path_for(tmp_path, arm, 0)
    lines = path.read_text().splitlines(keepends=True)
    header = json.loads(lines[0])
    old = header["header"]["shield"]
    del old["version"], old["reviser"]["one_sided"]  # version 1, before the field existed
    old["observation"]["knee_shape"], old["reviser"]["flag_rate_per"] = "double", "entry"
    path.write_text(json.dumps(header) + "\n" + "".join(lines[1:]))
    assert runner.run_one(off, arm, 0, tmp_path) == 0  # the same shield: nothing to do
    header["header"]["identity"] = CONFIG.identity()  # as if run without the override
    path.write_text(json.dumps(header) + "\n" + "".join(lines[1:]))
    with pytest.raises(records.RecordError, match="another shield configuration"):
        runner.run_one(CONFIG, arm, 0, tmp_path)


def test_records_carry_their_reward_constants_and_refuse_others(tmp_path: Path) -> None:
    """A header names the resolved reward; one written before headers did resumes as the
    defaults of its time (no failure penalty), one with other constants is refused."""
    arm = "idm-aggressive"
    runner.run_one(CONFIG, arm, 0, tmp_path)
    path = records.path_for(tmp_path, arm, 0)
    lines = path.read_text().splitlines(keepends=True)
    header = json.loads(lines[0])
    assert header["header"]["reward"]["failure_penalty"] == 0.0
    del header["header"]["reward"]  # written before headers carried it
    path.write_text(json.dumps(header) + "\n" + "".join(lines[1:]))
    assert runner.run_one(CONFIG, arm, 0, tmp_path) == 0  # the same constants: nothing to do
    header["header"]["reward"] = {**dataclasses.asdict(RewardConfig()), "failure_penalty": 5.0}
    path.write_text(json.dumps(header) + "\n" + "".join(lines[1:]))
    with pytest.raises(records.RecordError, match="other reward constants"):
        runner.run_one(CONFIG, arm, 0, tmp_path)


def record(
    run: int, episode: int, outcome: str, n: int = 10, mean: float = 1.0, var: float = 0.0
) -> EpisodeRecord:
    return EpisodeRecord(
        arm="a",
        run=run,
        episode=episode,
        seed=run,
        steps=n,
        outcome=outcome,
        speed_diff_n=n,
        speed_diff_mean=mean,
        speed_diff_var=var,
        interventions={"collision": 1} if outcome == "success" else {},
    )


def test_summary_numbers_by_hand() -> None:
    rows = [
        record(0, 1, "collision"),
        record(0, 2, "success", 10, 1.0, 0.5),
        record(0, 3, "success", 30, 3.0, 1.0),
        record(1, 1, "large_distance"),
        record(1, 2, "success", 20, 2.0, 0.0),
        record(1, 3, "collision"),
    ]
    s = report.summarise(rows)["a"]
    assert (s["episodes"], s["successes"], s["large_distance"], s["collision"]) == (6, 3, 1, 2)
    assert s["never_fails_after_per_run"] == [1, 3] and s["never_fails_after"] == 3
    # pooled over 60 steps: mean (10*1 + 30*3 + 20*2) / 60; E[x^2] from each episode's
    mean = (10 * 1 + 30 * 3 + 20 * 2) / 60
    second = (10 * (0.5 + 1) + 30 * (1 + 9) + 20 * (0 + 4)) / 60
    assert s["speed_difference_mean"] == pytest.approx(mean)
    assert s["speed_difference_variance"] == pytest.approx(second - mean**2)
    assert s["interventions"] == {"collision": 3}
    assert s["steps"] == 90 and s["revised_share"] == pytest.approx(3 / 90)
    assert "| a | 2 | 6 | 3 (50.0%) | 1 | 2 | 3 |" in report.table({"a": s})
    assert report.table({"a": s}).endswith(" | 3 (3.3%) |")  # revised: 3 of 90 steps
    first, second = s["per_run"]
    assert (first["successes"], first["large_distance"], first["collision"]) == (2, 0, 1)
    assert (second["successes"], second["large_distance"], second["collision"]) == (1, 1, 1)
    assert first["late_success_rate"] == pytest.approx(2 / 3)
    assert second["late_interventions_per_episode"] == pytest.approx(1 / 3)
    assert "| a | 1 | 1 | 3 | 1 (33.3%) | 1 | 1 | 3 | 1-3 | 33.3% | 0.3 | - |" in report.runs_table(
        {"a": s}
    )
    later = [record(0, 101, "success"), record(1, 101, "collision"), record(0, 250, "success")]
    blocks = report.summarise(rows + later)["a"]["per_100_episodes"]
    assert [b["episodes"] for b in blocks] == ["1-3", "101-101", "201-250"]
    assert [b["success_rate"] for b in blocks] == [0.5, 0.5, 1.0]
    assert [(b["large_distance"], b["collision"]) for b in blocks] == [(1, 2), (0, 1), (0, 0)]
    assert blocks[0]["interventions_per_episode"] == pytest.approx(3 / 6)
    many = [record(0, e, "collision" if e == 7 else "success") for e in range(1, 151)]
    [run] = report.summarise(many)["a"]["per_run"]
    assert (run["late_episodes"], run["late_success_rate"]) == ("51-150", 1.0)
    assert (run["episodes"], run["never_fails_after"]) == (150, 7)


def test_blocks_side_by_side_align_by_episode() -> None:
    long = [record(0, e, "collision" if e in (1, 150) else "success") for e in range(1, 201)]
    short = [record(0, e, "large_distance" if e == 2 else "success") for e in range(1, 121)]
    text = report.side_by_side(
        {"long": report.summarise(long)["a"], "short": report.summarise(short)["a"]}
    )
    assert text.splitlines()[0] == "Per block of 100 episodes, each cell long / short:"
    assert text.splitlines()[4:] == [
        "| 1-100 | 99.0% / 99.0% | 0 / 1 | 1 / 0 | 1.0 / 1.0 |",
        "| 101-200 / 101-120 | 99.0% / 100.0% | 0 / 0 | 1 / 0 | 1.0 / 1.0 |",
    ]
    only_long = report.side_by_side(
        {"short": report.summarise(short)["a"], "long": report.summarise(long)["a"]}
    )
    assert "| 101-120 / 101-200 | 100.0% / 99.0% |" in only_long
    late = [record(0, e, "success") for e in range(101, 111)]
    gap = report.side_by_side(
        {"early": report.summarise(short[:50])["a"], "late": report.summarise(late)["a"]}
    )
    assert gap.splitlines()[4:] == [
        "| 1-50 | 98.0% / - | 1 / - | 0 / - | 1.0 / - |",
        "| 101-110 | - / 100.0% | - / 0 | - / 0 | - / 1.0 |",
    ]


def test_partings_name_the_first_episode_that_went_differently() -> None:
    base = [record(0, e, "success") for e in range(1, 6)] + [
        record(1, e, "success") for e in range(1, 4)
    ]
    crashed = [record(0, e, "collision" if e == 4 else "success") for e in range(1, 6)] + [
        record(1, e, "success") for e in range(1, 3)
    ]
    assert report.parting(base, crashed) == {("a", 0): "4", ("a", 1): "none in 2"}
    slower = [dataclasses.replace(r, wall_s=9.0) for r in base]
    assert set(report.parting(base, slower).values()) == {"none in 5", "none in 3"}
    drifted = [
        dataclasses.replace(r, speed_diff_mean=1.0 + 1e-12) if r.episode >= 2 else r
        for r in crashed
    ]  # another machine's rounding, from episode 2 on
    assert report.parting(base, drifted) == {
        ("a", 0): "4 (rounding from 2)",
        ("a", 1): "none in 2 (rounding from 2)",
    }
    reseeded = [dataclasses.replace(r, seed=7) for r in base]
    assert report.parting(base, reseeded)[("a", 0)] == "other seed"
    assert report.parting(base, crashed[:5])[("a", 1)] == "-"
    text = report.partings_table(["base", "crashed", "slower"], [base, crashed, slower])
    assert text.splitlines()[2:] == [
        "| arm | run | crashed | slower |",
        "|---|---:|---:|---:|",
        "| a | 0 | 4 | none in 5 |",
        "| a | 1 | none in 2 | none in 3 |",
    ]


def test_report_writes_summary_table_and_figure(tmp_path: Path) -> None:
    runner.run_one(CONFIG, "idm-aggressive", 0, tmp_path)
    text, summary = report.write(tmp_path)
    assert summary["idm-aggressive"]["episodes"] == 8
    for name in ("summary.json", "table.md", "figure.png"):
        assert (tmp_path / name).stat().st_size > 0
    assert text.splitlines()[2].startswith("| idm-aggressive |")
    successes = summary["idm-aggressive"]["successes"]
    assert f"| idm-aggressive | 1-8 | {100 * successes / 8:.1f}% |" in text


def test_ddpg_is_deterministic_for_a_seed() -> None:
    def train(seed: int) -> list[float]:
        torch.set_num_threads(1)
        agent = DDPG(DDPGConfig(warmup=32), seed)
        rng = np.random.default_rng(0)
        for _ in range(80):
            obs = rng.uniform(0, 30, 4).astype(np.float32)
            agent.remember(obs, agent.act(obs), -1.0, obs, False)
            agent.update()
        probe = np.array([10.0, 40.0, 12.0, 0.0], np.float32)
        return [agent.act(probe, explore=False), agent.act(probe)]

    assert train(1) == train(1)
    assert train(1) != train(2)


class Sequenced:
    """A learner, a controller and an environment in one, writing down what happens in which
    order. The update and the step each wait (2 s at most) for the other to have started:
    only a step run beside the update lets both see it."""

    def __init__(self, update_first: bool) -> None:
        self.config = DDPGConfig(update_first=update_first)
        self.calls: list[str] = []
        self.updating, self.stepping = threading.Event(), threading.Event()
        self.met: list[bool] = []

    def act(self, obs: object) -> float:
        self.calls.append("act")
        return 0.0

    def update(self) -> None:
        self.updating.set()
        self.met.append(self.stepping.wait(2))
        self.calls.append("update")

    def step(self, action: object) -> tuple[object, float, bool, bool, dict[str, object]]:
        self.stepping.set()
        self.met.append(self.updating.wait(2))
        self.calls.append("step")
        return np.zeros(4, np.float32), 0.0, True, False, {"speed_difference": 0.0}

    def remember(self, *transition: object) -> None:
        self.calls.append("remember")


@pytest.mark.parametrize("update_first", [False, True])
def test_a_learner_that_updates_first_updates_while_the_shield_answers(update_first: bool) -> None:
    """The usual order updates after storing the step; ``update_first`` updates before the
    step is stored, and, given a thread to step the environment in (a remote shield's), both
    at once."""
    from concurrent.futures import ThreadPoolExecutor

    alone = Sequenced(update_first)
    runner.play(alone, alone, np.zeros(4, np.float32), alone)
    expected = (
        ["act", "update", "step", "remember"]
        if update_first
        else ["act", "step", "remember", "update"]
    )
    assert alone.calls == expected
    assert alone.met == [False, True]  # one after the other: the first waited in vain
    if update_first:
        beside = Sequenced(update_first)
        with ThreadPoolExecutor(1) as pool:
            runner.play(
                beside,
                beside,
                np.zeros(4, np.float32),
                beside,
                pool=pool,
            )
        assert beside.met == [True, True]  # each saw the other start: they ran together
        assert beside.calls[-1] == "remember"


def test_gzipped_records_report_the_same(tmp_path: Path) -> None:
    """Committed results keep their records gzipped; the report reads them unchanged."""
    plain, packed = tmp_path / "plain", tmp_path / "packed"
    runner.run_one(CONFIG, "idm-aggressive", 0, plain)
    source = records.path_for(plain, "idm-aggressive", 0)
    (packed / "records").mkdir(parents=True)
    (packed / "records" / (source.name + ".gz")).write_bytes(gzip.compress(source.read_bytes()))
    assert report.write(packed)[1] == report.write(plain)[1]
    (packed / "records" / source.name).write_bytes(source.read_bytes())
    with pytest.raises(records.RecordError, match="both plain and gzipped"):
        records.read_all(packed)
    (packed / "records" / source.name).unlink()
    (packed / "records" / (source.name + ".gz")).write_bytes(b"\x1f\x8b not really gzip")
    with pytest.raises(records.RecordError, match="damaged|gzip"):
        records.read_all(packed)


def test_a_finished_run_keeps_its_shield_model(tmp_path: Path) -> None:
    """A local shield's model outlives the run: OUT/models holds it as PUT /models/{name}
    takes it, with the state count the last episode recorded."""
    arm = "idm-aggressive+shield"
    runner.run_one(CONFIG, arm, 0, tmp_path)
    kept = json.loads(
        gzip.decompress((tmp_path / "models" / "idm-aggressive_shield__run00.json.gz").read_bytes())
    )
    model = Shield.from_snapshot(codec.from_json(kept["exact"]))
    last = records.read(records.path_for(tmp_path, arm, 0))[1][-1]
    assert model.n_states == last.n_states > 0
    assert model.counters.episodes == CONFIG.episodes


def test_a_stopped_run_goes_on_by_replaying(tmp_path: Path) -> None:
    """A run outside a lockstep group stops after the episode in which its stop says so, keeps
    its model there, and the same call later records what an unstopped run records."""
    whole, stopped = tmp_path / "whole", tmp_path / "stopped"
    arm = "idm-aggressive+shield"
    runner.run_one(CONFIG, arm, 0, whole)
    asked = iter(range(3))
    assert runner.run_one(CONFIG, arm, 0, stopped, stop=lambda: next(asked, None) is None) == 4
    kept = json.loads(
        gzip.decompress((stopped / "models" / "idm-aggressive_shield__run00.json.gz").read_bytes())
    )
    assert codec.from_json(kept["exact"])["counters"]["episodes"] == 4
    assert runner.run_one(CONFIG, arm, 0, stopped) == CONFIG.episodes - 4
    assert without_wall(records.read(records.path_for(stopped, arm, 0))[1]) == without_wall(
        records.read(records.path_for(whole, arm, 0))[1]
    )


def test_a_run_that_does_not_replay_says_what_differs(tmp_path: Path) -> None:
    """Floating point can come out differently on another processor or build, so records
    written elsewhere may not replay here: the refusal names what differs (the e-FSM's
    sources among it), and blames the code only when all of that is the same."""
    arm = "idm-aggressive"
    runner.run_one(CONFIG, arm, 0, tmp_path)
    path = records.path_for(tmp_path, arm, 0)
    header, *episodes = [json.loads(line) for line in path.read_text().splitlines()[:4]]
    episodes[1]["steps"] += 1  # episode 2 as another machine might have played it

    def write(versions: dict[str, str]) -> None:
        lines = [{"header": {**header["header"], "versions": versions}}, *episodes]
        path.write_text("".join(json.dumps(line) + "\n" for line in lines))

    write({**runner.versions(), "cpu": "Another CPU (AVX512)"})
    with pytest.raises(
        records.RecordError,
        match=r"episode 2 did not replay identically "
        r"\(the hardware differs \(written on Another CPU \(AVX512\), replayed "
        r"on .+\): the controller's arithmetic follows the CPU\)",
    ):
        runner.run_one(CONFIG, arm, 0, tmp_path)
    write({**runner.versions(), "core": "0" * 12})  # another e-FSM, the same libraries
    with pytest.raises(
        records.RecordError,
        match=r"\(the e-FSM has changed since \(core "
        r"000000000000 there, [0-9a-f]{12} here\)\)",
    ):
        runner.run_one(CONFIG, arm, 0, tmp_path)
    write({**runner.versions(), "torch": "1.0", "cpu": "Another CPU"})  # both named
    with pytest.raises(
        records.RecordError,
        match=r"\(the hardware differs \(written on Another "
        r"CPU, .+; the libraries differ \(torch 1.0 there, .+ here\)",
    ):
        runner.run_one(CONFIG, arm, 0, tmp_path)
    for written in (
        runner.versions(),
        {name: value for name, value in runner.versions().items() if name != "core"},
    ):  # (before headers named it)
        write(written)
        with pytest.raises(records.RecordError, match="the code has changed since"):
            runner.run_one(CONFIG, arm, 0, tmp_path)
    assert len(records.read(path)[1]) == 3  # refused, nothing appended


def test_a_gzipped_run_goes_on_unpacked(tmp_path: Path) -> None:
    """Committed results are gzipped; running the experiment again unpacks an unfinished run
    and goes on, replaying what was recorded, and leaves a finished one packed (a damaged
    archive is refused, untouched)."""
    whole, packed = tmp_path / "whole", tmp_path / "packed"
    arm = "idm-aggressive+shield"
    runner.run_one(CONFIG, arm, 0, whole)
    source = records.path_for(whole, arm, 0)
    archive = records.path_for(packed, arm, 0).with_suffix(".jsonl.gz")
    archive.parent.mkdir(parents=True)
    archive.write_bytes(b"\x1f\x8b not really gzip")
    with pytest.raises(records.RecordError, match="damaged|gzip"):
        runner.run_one(CONFIG, arm, 0, packed)
    assert sorted(archive.parent.iterdir()) == [archive]  # no empty plain file beside it
    archive.write_bytes(gzip.compress(b"".join(source.read_bytes().splitlines(True)[:4])))
    assert runner.run_one(CONFIG, arm, 0, packed) == CONFIG.episodes - 3
    assert not archive.exists()
    plain = records.path_for(packed, arm, 0)
    assert without_wall(records.read(plain)[1]) == without_wall(records.read(source)[1])
    archive.write_bytes(gzip.compress(plain.read_bytes()))  # finished and packed again
    plain.unlink()
    assert runner.run_one(CONFIG, arm, 0, packed) == 0
    assert sorted(archive.parent.iterdir()) == [archive]  # read where it is, not unpacked


def test_the_report_puts_ddpg_arms_beside_the_paper() -> None:
    """The paper's rows come first, then this experiment's in the same columns; other arms
    have no counterpart in the paper."""
    rows = [
        dataclasses.replace(record(run, e, "success" if e > 1 else "collision"), arm="ddpg+shield")
        for run in (0, 1)
        for e in (1, 2, 3)
    ]
    text = report.paper_table(report.summarise(rows))
    assert text is not None
    lines = text.splitlines()
    assert lines[2] == (
        "| paper: DDPG + e-FSM | 10 x 1500 | 14,719 (98.1%) | 76 | 205 | 68 | 2.0460 / 1.7800 |"
    )
    assert lines[3] == "| this: ddpg+shield | 2 x 3 | 4 (66.7%) | 0 | 2 | 1 | 1.0000 / 0.0000 |"
    assert report.paper_table(report.summarise([record(0, 1, "success")])) is None
    both = report.paper_table(
        report.summarise(rows + [dataclasses.replace(record(0, 1, "success"), arm="ddpg")])
    )
    assert both is not None and both.splitlines()[2].startswith(
        "| paper: DDPG | 10 x 1500 | 12,249 (81.6%) | 1,251 | 1,500 | - |"
    )


def test_report_of_each_runs_first_episodes(tmp_path: Path) -> None:
    """Runs stopped at different points are compared over the episodes all of them reached."""
    runner.run_one(CONFIG, "idm-aggressive", 0, tmp_path)
    shorter = dataclasses.replace(CONFIG, episodes=5)
    path = records.path_for(tmp_path, "idm-aggressive", 1)
    records.start(path, {"identity": "other run"}, CONFIG.episodes)
    for r in records.read(records.path_for(tmp_path, "idm-aggressive", 0))[1][: shorter.episodes]:
        records.append(path, dataclasses.replace(r, run=1))
    summary = report.write(tmp_path, 5)[1]["idm-aggressive"]
    assert summary["episodes"] == 10 and summary["episodes_per_run"] == [5, 5]
    assert json.loads((tmp_path / "summary.json").read_text())["episode_limit"] == 5
    assert report.write(tmp_path)[1]["idm-aggressive"]["episodes_per_run"] == [8, 5]
    result = cli("report", str(tmp_path), "--episodes", "6")
    assert result.returncode == 2
    assert (
        "run 1 of idm-aggressive has only 5 episodes; --episodes must be at most 5" in result.stderr
    )
    uneven = [record(0, e, "success") for e in range(1, 4)] + [record(1, 1, "success")]
    with pytest.raises(
        records.RecordError, match="run 1 of a has only 1 episodes; --episodes must be at most 1"
    ):  # the shortest run, not the first
        report.first_episodes(uneven, 4)
    assert report.first_episodes([], 4) == []  # an experiment with no episodes yet


def cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "client", *args], capture_output=True, text=True, timeout=120
    )


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (("run", "--arms", "ddpg,teleport"), "Invalid value for '--arms': unknown arm 'teleport'"),
        (("run", "--shield", "http://127.0.0.1:{port}", "--episodes", "1"), "unreachable"),
        (("report", "{tmp}/nothing"), "no record files"),
        (
            ("run", "--shield-config", '{"reviser": {"inspect": "every"}}'),
            "Invalid value for '--shield-config': reviser.inspect: expected one of",
        ),
        (
            ("run", "--shield-config", "{reviser: 1}"),
            "Invalid value for '--shield-config': not JSON: Expecting property name",
        ),
        (("run", "--shield-config", "[1]"), "'--shield-config': a JSON object {...}, not list"),
        (("run", "--reward", '{"penalty": 60}'), "Invalid value for '--reward': "),
        (("run", "--ddpg", '{"learning_rate": 1}'), "Invalid value for '--ddpg': "),
        (("run", "--ddpg", '{"gamma": 0.9'), "Invalid value for '--ddpg': not JSON"),
        (("run", "--runs", "ten"), "Invalid value for '--runs'"),
        (("run", "--runs", "0"), "Invalid value for '--runs'"),
        (("run", "--transport", "udp"), "Invalid value for '--transport'"),
        (("run", "--lead", "mars"), "Invalid value for '--lead'"),
        (("run", "--episodez", "5"), "No such option: --episodez"),
        (("runn",), "No such command 'runn'"),
    ],
)
def test_user_errors_are_one_clear_line(
    tmp_path: Path, args: tuple[str, ...], message: str
) -> None:
    args = tuple(
        a.replace("{port}", str(free_port())).replace("{tmp}", str(tmp_path)) for a in args
    )
    result = cli(*args, "--out", str(tmp_path / "out")) if args[0] == "run" else cli(*args)
    assert result.returncode == 2
    assert message in result.stderr and "Traceback" not in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()  # refused before anything ran


def test_the_help_of_run_names_every_option_whole_at_80_columns() -> None:
    result = subprocess.run(
        [sys.executable, "-m", "client", "run", "--help"],
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, "COLUMNS": "80"},
    )
    assert result.returncode == 0, result.stderr
    assert max(len(line) for line in result.stdout.splitlines()) <= 80
    for option in (
        "--arms",
        "--shield-config",
        "--checkpoint-minutes",
        "--stop-after",
        "--update-first",
        "--lockstep-runs",
        "--reward",
        "--ddpg",
    ):
        assert f"  {option} " in result.stdout or f"  {option}\n" in result.stdout


def test_a_run_says_first_what_it_will_run_and_how_to_make_it_shorter(tmp_path: Path) -> None:
    result = cli(
        "run",
        "--arms",
        "idm",
        "--runs",
        "2",
        "--episodes",
        "1",
        "--lead",
        "synthetic",
        "--workers",
        "1",
        "--out",
        str(tmp_path),
    )
    assert result.returncode == 0, result.stderr
    assert result.stderr.splitlines()[0] == (
        f"running idm: 2 x 1 episodes per arm (2 episodes of up to 800 steps) in 1 worker "
        f"process(es), records into {tmp_path}; shorter: --runs 1 --episodes 20, or "
        "--stop-after MINUTES (the same command goes on later)"
    )


def test_a_corrupt_record_file_is_one_clear_line(tmp_path: Path) -> None:
    (tmp_path / "records").mkdir()
    (tmp_path / "records" / "x__run00.jsonl").write_text("not json\n")
    result = cli("report", str(tmp_path))
    assert result.returncode == 2 and "not a record file" in result.stderr


def test_run_command_end_to_end(tmp_path: Path) -> None:
    result = cli(
        "run",
        "--arms",
        "idm,idm+shadow",
        "--runs",
        "2",
        "--episodes",
        "3",
        "--lead",
        "synthetic",
        "--workers",
        "2",
        "--out",
        str(tmp_path),
    )
    assert result.returncode == 0, result.stderr
    assert "| idm+shadow | 2 | 6 |" in result.stdout
    assert len(list((tmp_path / "records").glob("*.jsonl"))) == 4


def test_lockstep_command(tmp_path: Path) -> None:
    result = cli(
        "run",
        "--arms",
        "ddpg,idm",
        "--runs",
        "3",
        "--episodes",
        "2",
        "--lockstep",
        "--lockstep-runs",
        "2",
        "--lead",
        "synthetic",
        "--workers",
        "2",
        "--out",
        str(tmp_path),
    )
    assert result.returncode == 0, result.stderr
    assert "| ddpg | 3 | 6 |" in result.stdout and "| idm | 3 | 6 |" in result.stdout


def test_the_run_command_can_have_ddpg_update_first(tmp_path: Path) -> None:
    result = cli(
        "run",
        "--arms",
        "ddpg",
        "--runs",
        "1",
        "--episodes",
        "1",
        "--lead",
        "synthetic",
        "--update-first",
        "--out",
        str(tmp_path),
    )
    assert result.returncode == 0, result.stderr
    header = json.loads((tmp_path / "records" / "ddpg__run00.jsonl").read_text().splitlines()[0])[
        "header"
    ]
    assert header["config"]["ddpg"] == {"update_first": True}


def test_the_demo_trains_both_arms_in_lockstep_against_its_own_service(tmp_path: Path) -> None:
    result = cli("demo", "--runs", "2", "--episodes", "2", "--out", str(tmp_path))
    assert result.returncode == 0, result.stderr
    assert "| ddpg | 2 | 4 |" in result.stdout and "| ddpg+shield | 2 | 4 |" in result.stdout
    assert (tmp_path / "figure.png").exists()
    headers = [
        json.loads(path.read_text().splitlines()[0])["header"]
        for path in (tmp_path / "records").glob("*.jsonl")
    ]
    assert len(headers) == 4
    assert all(h["learning"]["lockstep"] for h in headers)
    assert all(h["config"]["shield"].startswith("http://127.0.0.1:") for h in headers)
    assert not list(tmp_path.glob("tmp*"))  # the service's data went with the service
    again = cli("demo", "--runs", "2", "--episodes", "2", "--out", str(tmp_path))
    assert again.returncode == 0, again.stderr
    assert (
        f"{tmp_path} already holds 8 of 8 episodes: reporting them without training; to "
        f"start afresh, remove {tmp_path}"
    ) in again.stdout
    assert "| ddpg+shield | 2 | 4 |" in again.stdout


def test_the_command_stops_runs_outside_lockstep_at_its_deadline(tmp_path: Path) -> None:
    command = (
        "run",
        "--arms",
        "idm",
        "--runs",
        "2",
        "--episodes",
        "30",
        "--lead",
        "synthetic",
        "--workers",
        "1",
        "--out",
        str(tmp_path),
    )
    first = cli(*command, "--stop-after", "0")
    assert first.returncode == 0, first.stderr
    assert "stopped at the deadline with 2 of 60 episodes; the same command goes on" in first.stdout
    assert not (tmp_path / "table.md").exists()
    then = cli(*command)
    assert then.returncode == 0, then.stderr
    assert "| idm | 2 | 60 |" in then.stdout


@pytest.mark.parametrize(
    ("options", "message"),
    [
        (["--lockstep-runs", "2"], "options of --lockstep"),
        (["--device", "cuda"], "options of --lockstep"),
        (["--checkpoint-minutes", "5"], "options of --lockstep"),
        (["--lockstep", "--device", "tpu"], "cpu or cuda"),
    ],
)
def test_lockstep_options_are_checked(tmp_path: Path, options: list[str], message: str) -> None:
    result = cli(
        "run",
        "--arms",
        "ddpg",
        "--runs",
        "1",
        "--episodes",
        "1",
        "--lead",
        "synthetic",
        "--out",
        str(tmp_path),
        *options,
    )
    assert result.returncode == 2 and message in result.stderr
    assert not (tmp_path / "records").exists()


def test_compare_puts_experiments_side_by_side(tmp_path: Path) -> None:
    """One row per directory and arm, each shielded row naming its configuration."""
    for name, overrides in (("default", "{}"), ("overwrite", '{"reviser":{"flags":"overwrite"}}')):
        result = cli(
            "run",
            "--arms",
            "idm-aggressive,idm-aggressive+shield",
            "--runs",
            "1",
            "--episodes",
            "2",
            "--lead",
            "synthetic",
            "--shield-config",
            overrides,
            "--out",
            str(tmp_path / name),
        )
        assert result.returncode == 0, result.stderr
    result = cli(
        "compare",
        str(tmp_path / "default"),
        str(tmp_path / "overwrite"),
        "--out",
        str(tmp_path / "table.md"),
    )
    assert result.returncode == 0, result.stderr
    rows = [line for line in result.stdout.splitlines() if line.startswith("| ")][1:]
    assert [row.split(" | ")[0] for row in rows] == [
        "| default: idm-aggressive",
        "| default: idm-aggressive+shield",
        "| overwrite: idm-aggressive",
        "| overwrite: idm-aggressive+shield",
    ]
    assert rows[3].endswith('`{"reviser":{"flags":"overwrite"}}` |')
    assert rows[0].endswith(" - |")
    assert (tmp_path / "table.md").read_text() == result.stdout
    first = cli(
        "compare", str(tmp_path / "default"), str(tmp_path / "overwrite"), "--episodes", "1"
    )
    assert first.returncode == 0, first.stderr
    counts = [row.split(" | ")[1:3] for row in first.stdout.splitlines() if ": idm" in row]
    assert counts == [["1", "1"]] * 4  # runs, episodes: each run's first episode only
    blocks = cli("compare", str(tmp_path / "default"), str(tmp_path / "overwrite"), "--blocks")
    assert blocks.returncode == 0, blocks.stderr
    assert blocks.stdout.startswith(result.stdout.rstrip("\n") + "\n\nPer block of 100")
    [row] = [line for line in blocks.stdout.splitlines() if line.startswith("| 1-2 |")]
    assert row.count(" / ") == 4 * 3  # four rows in each of four columns; one span of episodes
    too_many = cli("compare", str(tmp_path / "default"), "--episodes", "3")
    assert too_many.returncode == 2 and "--episodes must be at most 2" in too_many.stderr
    parted = cli("compare", str(tmp_path / "default"), str(tmp_path / "overwrite"), "--partings")
    assert parted.returncode == 0, parted.stderr
    rows = parted.stdout.split("Where each run parts")[1].splitlines()
    assert "| idm-aggressive | 0 | none in 2 |" in rows  # the shield does not touch this arm
    alone = cli("compare", str(tmp_path / "default"), "--partings")
    assert alone.returncode == 2 and "two experiments" in alone.stderr


def test_two_processes_never_write_one_run(tmp_path: Path) -> None:
    first = runner.Run.open(CONFIG, "idm-aggressive", 0, tmp_path, None)
    try:
        with pytest.raises(records.RecordError, match="another process is writing"):
            runner.Run.open(CONFIG, "idm-aggressive", 0, tmp_path, None)
    finally:
        first.close()
    runner.Run.open(CONFIG, "idm-aggressive", 0, tmp_path, None).close()  # free again


def process_state(pid: int) -> tuple[str, int] | None:
    """A process's state letter and parent, from /proc; None when it is gone."""
    try:
        fields = (Path("/proc") / str(pid) / "stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return None
    return fields[0], int(fields[1])


def alive(pid: int) -> bool:
    state = process_state(pid)
    return state is not None and state[0] != "Z"


def children(pid: int) -> list[int]:
    """The live (not zombie) processes whose parent is ``pid``."""
    pids = (int(entry.name) for entry in Path("/proc").iterdir() if entry.name.isdigit())
    return [
        child
        for child in pids
        if (state := process_state(child)) and state[0] != "Z" and state[1] == pid
    ]


@pytest.mark.skipif(sys.platform != "linux", reason="the workers' parent-death signal is Linux's")
def test_workers_end_with_a_killed_runner(tmp_path: Path) -> None:
    """kill -9 of `client run` leaves no worker appending to its records, and no process of
    its own (workers, the progress queue's manager) behind."""
    process = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "client",
            "run",
            "--arms",
            "idm",
            "--runs",
            "2",
            "--episodes",
            "2000",
            "--lead",
            "synthetic",
            "--workers",
            "2",
            "--out",
            str(tmp_path),
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    files = [records.path_for(tmp_path, "idm", run) for run in (0, 1)]

    def lines() -> list[int]:
        return [len(f.read_bytes().splitlines()) if f.exists() else 0 for f in files]

    deadline = time.monotonic() + 60
    while min(lines()) < 3 and time.monotonic() < deadline:
        time.sleep(0.1)
    assert min(lines()) >= 3, "the runs did not start"
    spawned = children(process.pid)
    assert len(spawned) >= 3  # two workers and the manager
    process.kill()
    process.wait()
    time.sleep(2)  # the workers' SIGTERM arrives at once; let any last episode land
    settled = lines()
    time.sleep(2)
    assert lines() == settled
    assert [pid for pid in spawned if alive(pid)] == []


@pytest.mark.skipif(sys.platform != "linux", reason="the parent-death signal is Linux's")
def test_the_demo_service_ends_with_a_killed_demo(tmp_path: Path) -> None:
    process = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "client",
            "demo",
            "--runs",
            "1",
            "--episodes",
            "2000",
            "--out",
            str(tmp_path),
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    deadline = time.monotonic() + 60
    while not list(tmp_path.glob("records/*.jsonl")) and time.monotonic() < deadline:
        time.sleep(0.1)
    services = [
        pid
        for pid in children(process.pid)
        if b"app\0serve" in Path(f"/proc/{pid}/cmdline").read_bytes()
    ]
    assert len(services) == 1, "the demo did not start its service"
    process.kill()
    process.wait()
    deadline = time.monotonic() + 10
    while alive(services[0]) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not alive(services[0])


def test_a_shielded_run_records_its_whole_shield_configuration(tmp_path: Path) -> None:
    """Overrides alone would not say what ``{}`` meant when the defaults were those of the
    code that ran: the header keeps the resolved configuration with the run's seed."""
    runner.Run.open(CONFIG, "idm-aggressive+shield", 0, tmp_path, None).close()
    runner.Run.open(CONFIG, "idm-aggressive", 0, tmp_path, None).close()
    header, _ = records.read(records.path_for(tmp_path, "idm-aggressive+shield", 0))
    assert header["shield"]["reviser"]["activate_after_episodes"] == 2  # the override
    assert header["shield"]["reviser"]["flags"] == "rate"  # a default
    assert header["shield"]["reviser"]["seed"] == header["seed"]
    plain, _ = records.read(records.path_for(tmp_path, "idm-aggressive", 0))
    assert plain["shield"] is None


def test_an_unreachable_shield_releases_the_run(tmp_path: Path) -> None:
    remote = dataclasses.replace(CONFIG, shield=f"http://127.0.0.1:{free_port()}")
    with pytest.raises(Exception, match="unreachable|connect") as caught:
        runner.Run.open(remote, "idm-aggressive+shield", 0, tmp_path, None)
    # the traceback (alive in ``caught``) keeps the failed call's frame: the file is free anyway
    assert caught.value.__traceback__ is not None
    records.claim(records.path_for(tmp_path, "idm-aggressive+shield", 0)).close()


def test_the_paper_protocol_script_runs_every_shielded_run_on_its_own_service(
    tmp_path: Path,
) -> None:
    """results/scripts/paper-protocol.sh at a toy size: its services start, each shielded run
    gets one, the report is written and the services are gone afterwards."""
    root = Path(__file__).resolve().parents[2]
    port = free_port()
    env = {
        **os.environ,
        "RUNS": "2",
        "EPISODES": "2",
        "PORT": str(port),
        "PYTHON": sys.executable,
        "LOG_LEVEL": "info",
    }  # info: every request logged
    script = root / "results/scripts/paper-protocol.sh"
    result = subprocess.run(
        ["bash", str(script), str(tmp_path)], env=env, capture_output=True, text=True, timeout=300
    )
    assert result.returncode == 0, result.stderr
    headers, episodes = records.read_all(tmp_path)
    shields = {h["config"]["shield"] for h in headers}
    assert shields == {f"http://127.0.0.1:{port},http://127.0.0.1:{port + 1}"}
    assert len(episodes) == 2 * 2 * 2
    for run in (0, 1):  # each service log shows the one model it held
        log = (tmp_path / "services" / f"shield-{run}.log").read_text()
        assert f"exp-ddpg-shield-{run}" in log and f"exp-ddpg-shield-{1 - run}" not in log
    assert "wall:" in (tmp_path / "machine.txt").read_text()
    assert (tmp_path / "table.md").exists()
    for offset in (0, 1):
        with pytest.raises(httpx.TransportError):
            httpx.get(f"http://127.0.0.1:{port + offset}/healthz", timeout=1)


def test_the_paper_protocol_script_trains_in_lockstep_groups_against_batch_services(
    tmp_path: Path,
) -> None:
    """LOCKSTEP=1 TRANSPORT=batch SERVICES=2 SHIELD_CONFIG: the shielded runs' models spread
    over two services with the overrides, the arms train in lockstep groups of their own
    sizes, and machine.txt says so."""
    root = Path(__file__).resolve().parents[2]
    port = free_port()
    env = {
        **os.environ,
        "RUNS": "3",
        "EPISODES": "2",
        "PORT": str(port),
        "PYTHON": sys.executable,
        "LOCKSTEP": "1",
        "GROUP": "2",
        "DDPG_GROUP": "3",
        "TRANSPORT": "batch",
        "SERVICES": "2",
        "LOG_LEVEL": "info",
        "SHIELD_CONFIG": '{"reviser": {"flags": "overwrite"}}',
    }
    script = root / "results/scripts/paper-protocol.sh"
    result = subprocess.run(
        ["bash", str(script), str(tmp_path)], env=env, capture_output=True, text=True, timeout=300
    )
    assert result.returncode == 0, result.stderr
    headers, episodes = records.read_all(tmp_path)
    assert all(h["config"]["shield_config"] == {"reviser": {"flags": "overwrite"}} for h in headers)
    assert {h["shield"]["reviser"]["flags"] for h in headers if h["shield"]} == {"overwrite"}
    assert {h["config"]["shield"] for h in headers} == {
        f"http://127.0.0.1:{port},http://127.0.0.1:{port + 1}"
    }
    assert {h["config"]["transport"] for h in headers} == {"batch"}
    assert all(h["learning"] == {"lockstep": True, "device": "cpu"} for h in headers)
    assert len(episodes) == 2 * 3 * 2
    for service in (0, 1):
        log = (tmp_path / "services" / f"shield-{service}.log").read_text()
        assert "POST /revise/batch" in log and "/ws" not in log
    machine = (tmp_path / "machine.txt").read_text()
    assert "ddpg in groups of 3 runs, ddpg+shield in groups of 2" in machine
    assert "2 shield service(s), batch" in machine and "wall:" in machine
    assert 'shield overrides: {"reviser": {"flags": "overwrite"}}' in machine
    for offset in (0, 1):
        with pytest.raises(httpx.TransportError):
            httpx.get(f"http://127.0.0.1:{port + offset}/healthz", timeout=1)


def test_the_paper_protocol_script_refuses_an_unknown_transport(tmp_path: Path) -> None:
    root = Path(__file__).resolve().parents[2]
    env = {**os.environ, "PYTHON": sys.executable, "TRANSPORT": "http"}
    script = root / "results/scripts/paper-protocol.sh"
    result = subprocess.run(
        ["bash", str(script), str(tmp_path)], env=env, capture_output=True, text=True, timeout=60
    )
    assert result.returncode == 2
    assert result.stderr.strip() == "TRANSPORT: ws or batch, not http"


def test_a_traced_run_keeps_every_decision_once_even_when_resumed(tmp_path: Path) -> None:
    arm = "idm-aggressive+shield"
    runner.run_one(CONFIG, arm, 0, tmp_path, trace=True)
    path = records.path_for(tmp_path, arm, 0)
    path.write_text("".join(path.read_text().splitlines(keepends=True)[:4]))  # 3 episodes
    assert runner.run_one(CONFIG, arm, 0, tmp_path, trace=True) == 5  # replays 3, adds 5
    rows = trace.read(trace.path_for(tmp_path, arm, 0))
    episodes = records.read(records.path_for(tmp_path, arm, 0))[1]
    assert len(rows) == sum(e.steps for e in episodes)  # no replayed step twice
    assert [sum(r["e"] == e.episode for r in rows) for e in episodes] == [e.steps for e in episodes]
    revised = [r for r in rows if r["r"].startswith("revised")]
    assert revised and len(revised) == sum(sum(e.interventions.values()) for e in episodes)
    assert {r["r"] for r in rows if r["e"] <= 2} <= {"inactive", "cold_start"}  # not active yet
    runner.run_one(CONFIG, "idm-aggressive", 0, tmp_path, trace=True)
    assert not trace.path_for(tmp_path, "idm-aggressive", 0).exists()  # nothing to trace


def test_the_trace_command_tells_where_the_shield_revised(tmp_path: Path) -> None:
    result = cli(
        "run",
        "--arms",
        "ddpg+shield",
        "--runs",
        "1",
        "--episodes",
        "3",
        "--lead",
        "synthetic",
        "--out",
        str(tmp_path),
        "--trace",
        "--lockstep",
        "--shield-config",
        '{"reviser": {"activate_after_episodes": 1, "flag_min_rate": 0.0001}}',
    )
    assert result.returncode == 0, result.stderr
    rows = trace.read(trace.path_for(tmp_path, "ddpg+shield", 0))
    assert len(rows) == sum(e.steps for e in records.read_all(tmp_path)[1])
    result = cli("trace", str(tmp_path))
    assert result.returncode == 0, result.stderr
    assert "## ddpg+shield: 2 episodes with the reviser on (of 3 traced)" in result.stdout
    assert "| headway (m) | steps | revised against collision |" in result.stdout
    by_reason = result.stdout.split("Decisions by reason")[1].split("\n\n")[1].splitlines()
    header = [c.strip() for c in by_reason[0].strip("|").split("|")]
    counts = [int(c) for c in by_reason[2].strip("|").split("|")[1:]]
    assert header[0] == "episodes" and by_reason[2].startswith("| 1-50 |")
    assert sum(counts) == len(rows)  # every traced decision counted once
    origins = result.stdout.split("Where the failures came from")[1].split("\n\n")[1]
    failed = sum(
        int(c) for line in origins.splitlines()[2:] for c in line.strip("|").split("|")[3:5]
    )
    assert failed == sum(e.outcome != "success" for e in records.read_all(tmp_path)[1]) > 0
    sizes = result.stdout.split("How far the revisions moved the action")[1].split("\n\n")[1]
    overall = {
        cells[0]: (int(cells[2]), float(cells[3]))
        for cells in (
            [c.strip() for c in line.strip("|").split("|")] for line in sizes.splitlines()[2:]
        )
        if cells[1] == "every step"
    }
    for criterion in ("collision", "large_distance"):  # counted by the proposal's verdict
        revised = [r for r in rows if r["v"] == criterion and r["r"].startswith("revised")]
        if revised:
            assert overall[criterion][0] == len(revised)
            moved = [r["a"] - r["p"] for r in revised]
            assert overall[criterion][1] == pytest.approx(float(np.median(moved)), abs=5e-4)
    assert overall  # this run revised
    assert (tmp_path / "trace.md").read_text().strip() == result.stdout.strip()
    missing = cli("trace", str(tmp_path / "elsewhere"))
    assert missing.returncode == 2 and len(missing.stderr.strip().splitlines()) == 1
    path = trace.path_for(tmp_path, "ddpg+shield", 0)
    path.write_bytes(path.read_bytes()[:-20])  # a trace cut short
    damaged = cli("trace", str(tmp_path))
    assert damaged.returncode == 2 and "damaged trace" in damaged.stderr
    assert len(damaged.stderr.strip().splitlines()) == 1


def test_compare_keeps_experiments_of_the_same_name_apart(tmp_path: Path) -> None:
    short = dataclasses.replace(CONFIG, episodes=2)
    for seed in (3, 4):
        runner.run_one(
            dataclasses.replace(short, seed=seed),
            "idm-aggressive",
            0,
            tmp_path / f"seed-{seed}" / "idm",
        )
    text = report.compare([tmp_path / "seed-3" / "idm", tmp_path / "seed-4" / "idm"])
    rows = [line.split(" | ")[0] for line in text.splitlines()[2:]]
    assert rows == ["| seed-3/idm: idm-aggressive", "| seed-4/idm: idm-aggressive"]
    with pytest.raises(records.RecordError, match="given twice"):
        report.compare([tmp_path / "seed-3" / "idm", tmp_path / "seed-3" / "idm"])


def test_the_experiment_entry_point_lists_and_refuses_an_unknown_name() -> None:
    root = Path(__file__).resolve().parents[2]
    listed = subprocess.run(
        ["bash", str(root / "scripts/experiment")], capture_output=True, text=True, timeout=30
    )
    assert listed.returncode == 0
    names = [line.split()[0] for line in listed.stdout.splitlines()]
    assert "paper-protocol" in names and "default-switch" in names
    unknown = subprocess.run(
        ["bash", str(root / "scripts/experiment"), "no-such"],
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert unknown.returncode == 2 and "scripts/experiment lists them" in unknown.stderr
