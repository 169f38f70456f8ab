"""``python -m client run | report | compare | trace | demo``: car-following experiments."""

from __future__ import annotations

import contextlib
import json
import os
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from functools import partial
from pathlib import Path
from typing import Annotated, NoReturn

import httpx
import typer

from app.core import ShieldConfig, ShieldError
from client.experiment import checkpoint, parallel, report, runner
from client.experiment.progress import Progress
from client.experiment.records import RecordError, read_all
from client.experiment.trace import analyse as analyse_traces
from client.shield import ShieldAPIError, ShieldClient, ShieldUnavailable
from client.sim.car_following import RewardConfig

CHECKPOINT_MINUTES = 10.0  # how often lockstep groups save their state by default
cli = typer.Typer(add_completion=False, no_args_is_help=True, pretty_exceptions_enable=False,
                  help=__doc__)


def fail(message: str) -> NoReturn:
    typer.secho(f"error: {message}", err=True, fg="red")
    raise typer.Exit(2)


def experiment(arms: str, runs: int, episodes: int, seed: int, shield: str, transport: str,
               out: Path, workers: int, token: str | None, lead: str,
               shield_config: str = "{}", lockstep: int = 0, trace: bool = False,
               device: str = "cpu", checkpoint_every: float | None = None,
               deadline: float | None = None, update_first: bool = False,
               reward: str = "{}", ddpg: str = "{}") -> str:
    """Run, then report (or, stopped at ``deadline``, say how to go on); every failure a user
    can cause becomes one line."""
    try:
        overrides = json.loads(shield_config)
        ShieldConfig.from_dict(overrides)  # refuse a bad configuration before any run starts
        config = runner.ExperimentConfig(
            arms=tuple(a.strip() for a in arms.split(",") if a.strip()), runs=runs,
            episodes=episodes, seed=seed, shield=shield, transport=transport,  # type: ignore[arg-type]
            lead=lead, shield_config=overrides,  # type: ignore[arg-type]
            ddpg={**({"update_first": True} if update_first else {}), **json.loads(ddpg)},
            reward=json.loads(reward))
        try:
            RewardConfig(**config.reward)  # refuse an unknown reward constant before any run
        except TypeError as error:
            fail(f"reward: {error}")
        from client.agents.ddpg import DDPGConfig  # torch: only when a run starts

        try:
            DDPGConfig(**config.ddpg)
        except TypeError as error:
            fail(f"ddpg: {error}")
        if shield != "local":
            for url in config.shield_urls:
                with contextlib.closing(ShieldClient(url, token=token)) as probe:
                    probe.health()
        total = len(config.arms) * runs * episodes
        with Progress(total, recorded(out, config.arms)) as progress:
            parallel.run_all(config, out, workers, token, progress, lockstep, trace, device,
                             checkpoint_every, deadline)
        if deadline is not None and parallel.past(deadline):
            done = recorded(out, config.arms)
            if done < total:
                groups = len(checkpoint.pending(out))
                saved = (f", {groups} group(s) checkpointed in {out / checkpoint.DIRECTORY}"
                         if groups else "")
                return (f"stopped at the deadline with {done} of {total} episodes{saved}; "
                        f"the same command goes on from there")
        text, _ = report.write(out)
    except ShieldError as error:
        fail(f"shield configuration: {error.field}: {error.message}")
    except (ValueError, RecordError, ShieldUnavailable, ShieldAPIError) as error:
        fail(str(error))
    return text


def recorded(out: Path, arms: tuple[str, ...]) -> int:
    """Episodes of ``arms`` already recorded in ``out``."""
    if not any((out / "records").glob("*.jsonl*")):
        return 0
    return sum(r.arm in arms for r in read_all(out)[1])


@cli.command()
def run(
    arms: Annotated[str, typer.Option(help="Comma-separated: ddpg, idm, idm-aggressive, "
                                            "random, each optionally +shield or +shadow.")]
    = "ddpg,ddpg+shield",
    runs: Annotated[int, typer.Option(min=1)] = 10,
    episodes: Annotated[int, typer.Option(min=1)] = 1500,
    seed: Annotated[int, typer.Option(help="Base seed; runs get seeds spawned from it.")] = 1000,
    shield: Annotated[str, typer.Option(
        help="'local', or shield service URLs, comma-separated: run i uses the i-th in turn.")]
    = "local",
    transport: Annotated[str, typer.Option(help="http, ws or batch (remote shields).")] = "ws",
    out: Annotated[Path, typer.Option(help="Records, summary, table and figure go here.")]
    = Path("runs/experiment"),
    workers: Annotated[int, typer.Option(min=1, help="Runs in parallel processes.")]
    = max(1, os.cpu_count() or 1),
    token: Annotated[str | None, typer.Option(envvar="SHIELD_TOKEN")] = None,
    lead: Annotated[str, typer.Option(help="train, evaluation, epa or synthetic.")] = "train",
    shield_config: Annotated[str, typer.Option(
        help='Overrides of the shield configuration as JSON, e.g. '
             '\'{"reviser": {"inspect": "first_index"}}\' (ablations).')] = "{}",
    lockstep: Annotated[bool, typer.Option(
        help="Train the runs of each DDPG arm together in one process, one batched update "
             "for all (equal to separate runs within rounding).")] = False,
    lockstep_runs: Annotated[int | None, typer.Option(
        min=1, help="With --lockstep: runs per process (default: all the runs of an arm).")]
    = None,
    device: Annotated[str, typer.Option(
        help="With --lockstep: where the batched updates run, cpu or cuda (a CUDA graph).")]
    = "cpu",
    trace: Annotated[bool, typer.Option(
        help="Also write every decision of the shielded runs to OUT/traces (see 'trace').")]
    = False,
    checkpoint_minutes: Annotated[float | None, typer.Option(
        min=0, help="With --lockstep: save each group's state to OUT/checkpoints this often, "
                    "to go on from there after a crash (default 10; 0: never).")] = None,
    stop_after: Annotated[float | None, typer.Option(
        min=0, help="Stop after this many minutes: lockstep groups save their state, other "
                    "runs finish their episode; the same command goes on from there.")] = None,
    update_first: Annotated[bool, typer.Option(
        help="DDPG updates before each step instead of after it, so that it learns while a "
             "shield service answers: faster over the network, the same records over every "
             "transport, not those of the usual order.")] = False,
    reward: Annotated[str, typer.Option(
        help='Reward constants as JSON, e.g. \'{"failure_penalty": 60}\' (the paper\'s '
             'Eqs. 10-12 and none by default).')] = "{}",
    ddpg: Annotated[str, typer.Option(
        help='DDPG settings as JSON, e.g. \'{"gamma": 0.99}\' (the paper\'s values, and '
             'this project\'s where it gives none, by default).')] = "{}",
) -> None:
    """Run arms x runs x episodes (resumable: run it again to continue), then report."""
    if not lockstep and (lockstep_runs is not None or device != "cpu"
                         or checkpoint_minutes is not None):
        fail("--lockstep-runs, --device and --checkpoint-minutes are options of --lockstep")
    if trace and (checkpoint_minutes or stop_after is not None):
        fail("--trace: a traced experiment replays from the start, without checkpoints")
    if device not in ("cpu", "cuda"):
        fail(f"--device: cpu or cuda, not {device!r}")
    if device == "cuda":
        import torch

        if not torch.cuda.is_available():
            fail("--device cuda: no CUDA device here")
    group = (lockstep_runs or runs) if lockstep else 0
    minutes = CHECKPOINT_MINUTES if checkpoint_minutes is None else checkpoint_minutes
    every = 60.0 * minutes if lockstep and minutes and not trace else None
    deadline = None if stop_after is None else time.time() + 60.0 * stop_after
    typer.echo(experiment(arms, runs, episodes, seed, shield, transport, out, workers, token,
                          lead, shield_config, group, trace, device, every, deadline,
                          update_first, reward, ddpg))
    if (out / "table.md").exists() and not checkpoint.pending(out):
        typer.echo(f"\nrecords, summary.json, table.md and figure.png in {out}")


@cli.command("report")
def report_command(
    directory: Path,
    episodes: Annotated[int | None, typer.Option(
        min=1, help="Only each run's first N episodes (runs stopped at different points).")]
    = None,
) -> None:
    """The paper's table and figure from the records in DIRECTORY."""
    try:
        text, _ = report.write(directory, episodes)
    except RecordError as error:
        fail(str(error))
    typer.echo(text)
    typer.echo(f"\nsummary.json, table.md and figure.png in {directory}")


@cli.command("compare")
def compare_command(
    directories: list[Path],
    out: Annotated[Path | None, typer.Option(help="Also write the table here.")] = None,
    episodes: Annotated[int | None, typer.Option(
        min=1, help="Only each run's first N episodes (runs stopped at different points).")]
    = None,
    blocks: Annotated[bool, typer.Option(
        help="Also a table per block of 100 episodes, the rows side by side in each cell.")]
    = False,
    partings: Annotated[bool, typer.Option(
        help="Also where each run parts from the same run of the first experiment.")]
    = False,
) -> None:
    """One table over the experiments in DIRECTORIES (ablations): a row per directory and arm."""
    try:
        text = report.compare(directories, episodes, blocks, partings)
    except RecordError as error:
        fail(str(error))
    if out is not None:
        out.write_text(text + "\n")
    typer.echo(text)


@cli.command("trace")
def trace_command(directory: Path) -> None:
    """Where the shield revised and whether it saw each failure coming, from the step traces
    of an experiment run with --trace (also written to DIRECTORY/trace.md)."""
    try:
        text = analyse_traces(directory)
    except RecordError as error:
        fail(str(error))
    (directory / "trace.md").write_text(text)
    typer.echo(text)


@contextlib.contextmanager
def service(data_dir: Path) -> Iterator[str]:
    """The shield service as its own process on a free local port."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    url = f"http://127.0.0.1:{port}"
    log = open(data_dir.parent / "shield.log", "wb")
    process = subprocess.Popen(  # ends with this process, even one killed outright
        [sys.executable, "-m", "app", "serve", "--port", str(port), "--data-dir", str(data_dir),
         "--fsync", "never", "--log-level", "warning"], stdout=log, stderr=subprocess.STDOUT,
        preexec_fn=partial(parallel.die_with_parent, os.getpid()))
    try:
        deadline = time.monotonic() + 120  # a first start compiles the core: about 15 s here
        while True:
            if process.poll() is not None:
                fail(f"the shield service exited; see {log.name}")
            try:
                if httpx.get(url + "/readyz", timeout=1).status_code == 200:
                    break
            except httpx.TransportError:
                time.sleep(0.1)
            if time.monotonic() > deadline:
                fail(f"the shield service did not answer within 120 s; see {log.name}")
        yield url
    finally:
        process.terminate()
        process.wait(10)
        log.close()


@cli.command()
def demo(
    runs: Annotated[int, typer.Option(min=1)] = 2,
    episodes: Annotated[int, typer.Option(min=1)] = 120,
    seed: int = 1000,
    out: Path = Path("runs/demo"),
    transport: str = "ws",
    workers: Annotated[int, typer.Option(min=1)] = max(1, os.cpu_count() or 1),
    lockstep: Annotated[bool, typer.Option(
        help="Train the runs of each arm together, one batched update for all, the arms in "
             "parallel: on two cores the longest arm then sets the pace, not both arms one "
             "after the other.")] = True,
) -> None:
    """Start the shield service, train DDPG with and without it over the network, report."""
    out.mkdir(parents=True, exist_ok=True)
    arms = "ddpg,ddpg+shield"
    try:
        done = recorded(out, tuple(arms.split(",")))
    except RecordError as error:
        fail(str(error))
    total = 2 * runs * episodes
    if done:
        what = ("reporting them without training" if done >= total
                else "going on from them, not training them again")
        typer.echo(f"{out} already holds {min(done, total)} of {total} episodes: {what}; to "
                   f"start afresh, remove {out} or pass another --out")
    with tempfile.TemporaryDirectory(dir=out) as tmp, service(Path(tmp) / "data") as url:
        typer.echo(f"shield service at {url}; {runs} runs x {episodes} episodes per arm")
        text = experiment(arms, runs, episodes, seed, url, transport, out,
                          workers, None, "train", lockstep=runs if lockstep else 0)
    typer.echo(text)
    typer.echo(f"\nfigure: {out / 'figure.png'}; records and summary.json in {out}")


if __name__ == "__main__":
    cli()
