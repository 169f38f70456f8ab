"""``python -m client run | report | compare | trace | demo``: car-following experiments.

Every error on the command line is one line that names the option at fault (exit status 2).
"""

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
from typing import Annotated, Any, Literal, NoReturn

import httpx
import typer

from app.core import ShieldConfig, ShieldError
from client.experiment import checkpoint, parallel, report, runner
from client.experiment.progress import Progress
from client.experiment.records import RecordError, read_all
from client.experiment.trace import analyse as analyse_traces
from client.shield import ShieldAPIError, ShieldClient, ShieldUnavailable
from client.sim.car_following import MAX_STEPS, RewardConfig

CHECKPOINT_MINUTES = 10.0  # how often lockstep groups save their state by default
Transport = Literal["http", "ws", "batch"]
Lead = Literal["train", "evaluation", "epa", "synthetic"]
cli = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
    help=__doc__,
)  # plain help: readable at 80 columns


def fail(message: str) -> NoReturn:
    typer.secho(f"error: {message}", err=True, fg="red")
    raise typer.Exit(2)


def json_object(text: str) -> dict[str, Any]:
    """An option's JSON object, or the reason it is not one."""
    try:
        value = json.loads(text)
    except ValueError as error:
        raise typer.BadParameter(f"not JSON: {error}") from None
    if not isinstance(value, dict):
        raise typer.BadParameter("a JSON object {...}, not " + type(value).__name__)
    return value


def arms_option(text: str) -> str:
    """``--arms``: every arm one that :func:`runner.parse_arm` knows."""
    try:
        for arm in text.split(","):
            runner.parse_arm(arm.strip())
    except ValueError as error:
        raise typer.BadParameter(str(error)) from None
    return text


def shield_config_option(text: str) -> str:
    """``--shield-config``: overrides that make a valid shield configuration."""
    try:
        ShieldConfig.from_dict(json_object(text))
    except ShieldError as error:
        raise typer.BadParameter(
            f"{error.field}: {error.message}" if error.field else error.message
        ) from None
    return text


def reward_option(text: str) -> str:
    """``--reward``: constants that :class:`RewardConfig` has."""
    try:
        RewardConfig(**json_object(text))
    except TypeError as error:
        raise typer.BadParameter(str(error)) from None
    return text


def ddpg_option(text: str) -> str:
    """``--ddpg``: settings that :class:`~client.agents.ddpg.DDPGConfig` has."""
    from client.agents.ddpg import DDPGConfig  # torch: only when a run is asked for

    try:
        DDPGConfig(**json_object(text))
    except TypeError as error:
        raise typer.BadParameter(str(error)) from None
    return text


def experiment(
    arms: str,
    runs: int,
    episodes: int,
    seed: int,
    shield: str,
    transport: Transport,
    out: Path,
    workers: int,
    token: str | None,
    lead: Lead,
    shield_config: str = "{}",
    lockstep: int = 0,
    trace: bool = False,
    device: str = "cpu",
    checkpoint_every: float | None = None,
    deadline: float | None = None,
    update_first: bool = False,
    reward: str = "{}",
    ddpg: str = "{}",
    shorter: str = "",
) -> str:
    """Say what will run (and ``shorter``: how to make it shorter), run, then report (or,
    stopped at ``deadline``, say how to go on); every failure a user can cause becomes one
    line. The JSON options are checked by their options' callbacks."""
    try:
        config = runner.ExperimentConfig(
            arms=tuple(a.strip() for a in arms.split(",") if a.strip()),
            runs=runs,
            episodes=episodes,
            seed=seed,
            shield=shield,
            transport=transport,
            lead=lead,
            shield_config=json.loads(shield_config),
            ddpg={**({"update_first": True} if update_first else {}), **json.loads(ddpg)},
            reward=json.loads(reward),
        )
        if shield != "local":
            for url in config.shield_urls:
                with contextlib.closing(ShieldClient(url, token=token)) as probe:
                    probe.health()
        total = len(config.arms) * runs * episodes
        done = recorded(out, config.arms)
        typer.echo(
            f"{'going on with' if done else 'running'} {', '.join(config.arms)}: "
            f"{runs} x {episodes} episodes per arm ({total:,} episodes of up to "
            f"{MAX_STEPS} steps{f', {done:,} done' if done else ''}) in {workers} "
            f"worker process(es), records into {out}{shorter}",
            err=True,
        )
        with Progress(total, done) as progress:
            parallel.run_all(
                config,
                out,
                workers,
                token,
                progress,
                lockstep,
                trace,
                device,
                checkpoint_every,
                deadline,
            )
        if deadline is not None and parallel.past(deadline):
            done = recorded(out, config.arms)
            if done < total:
                groups = len(checkpoint.pending(out))
                saved = (
                    f", {groups} group(s) checkpointed in {out / checkpoint.DIRECTORY}"
                    if groups
                    else ""
                )
                return (
                    f"stopped at the deadline with {done} of {total} episodes{saved}; "
                    f"the same command goes on from there"
                )
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
    arms: Annotated[
        str,
        typer.Option(
            callback=arms_option,
            help="Comma-separated: ddpg, idm, idm-aggressive, random, "
            "each optionally +shield or +shadow.",
        ),
    ] = "ddpg,ddpg+shield",
    runs: Annotated[int, typer.Option(min=1)] = 10,
    episodes: Annotated[int, typer.Option(min=1)] = 1500,
    seed: Annotated[int, typer.Option(help="Base seed; runs get seeds spawned from it.")] = 1000,
    shield: Annotated[
        str,
        typer.Option(
            help="'local', or shield service URLs, comma-separated: run i uses the i-th in turn."
        ),
    ] = "local",
    transport: Annotated[Transport, typer.Option(help="How remote shields are reached.")] = "ws",
    out: Annotated[Path, typer.Option(help="Records, summary, table and figure go here.")] = Path(
        "runs/experiment"
    ),
    workers: Annotated[int, typer.Option(min=1, help="Runs in parallel processes.")] = max(
        1, os.cpu_count() or 1
    ),
    token: Annotated[str | None, typer.Option(envvar="SHIELD_TOKEN")] = None,
    lead: Annotated[Lead, typer.Option(help="The lead vehicle's speed profiles.")] = "train",
    shield_config: Annotated[
        str,
        typer.Option(
            callback=shield_config_option,
            help="Overrides of the shield configuration as JSON, e.g. "
            '\'{"reviser": {"inspect": "first_index"}}\' (ablations).',
        ),
    ] = "{}",
    lockstep: Annotated[
        bool,
        typer.Option(
            "--lockstep",
            help="Train the runs of each DDPG arm together in one process, one batched update "
            "for all (equal to separate runs within rounding).",
        ),
    ] = False,
    lockstep_runs: Annotated[
        int | None,
        typer.Option(
            min=1, help="With --lockstep: runs per process (default: all the runs of an arm)."
        ),
    ] = None,
    device: Annotated[
        str,
        typer.Option(
            help="With --lockstep: where the batched updates run, cpu or cuda (a CUDA graph)."
        ),
    ] = "cpu",
    trace: Annotated[
        bool,
        typer.Option(
            "--trace",
            help="Also write every decision of the shielded runs to OUT/traces (see 'trace').",
        ),
    ] = False,
    checkpoint_minutes: Annotated[
        float | None,
        typer.Option(
            min=0,
            help="With --lockstep: save each group's state to OUT/checkpoints this often, "
            "to go on from there after a crash (default 10; 0: never).",
        ),
    ] = None,
    stop_after: Annotated[
        float | None,
        typer.Option(
            min=0,
            help="Stop after this many minutes: lockstep groups save their state, other "
            "runs finish their episode; the same command goes on from there.",
        ),
    ] = None,
    update_first: Annotated[
        bool,
        typer.Option(
            "--update-first",
            help="DDPG updates before each step instead of after it, so that it learns while a "
            "shield service answers: faster over the network, the same records over every "
            "transport, not those of the usual order.",
        ),
    ] = False,
    reward: Annotated[
        str,
        typer.Option(
            callback=reward_option,
            help="Reward constants as JSON, e.g. '{\"failure_penalty\": 60}' (the paper's "
            "Eqs. 10-12 and none by default).",
        ),
    ] = "{}",
    ddpg: Annotated[
        str,
        typer.Option(
            callback=ddpg_option,
            help="DDPG settings as JSON, e.g. '{\"gamma\": 0.99}' (the paper's values, and "
            "this project's where it gives none, by default).",
        ),
    ] = "{}",
) -> None:
    """Run arms x runs x episodes (resumable: run it again to continue), then report."""
    if not lockstep and (
        lockstep_runs is not None or device != "cpu" or checkpoint_minutes is not None
    ):
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
    shorter = (
        "; shorter: --runs 1 --episodes 20, or --stop-after MINUTES "
        "(the same command goes on later)"
    )
    typer.echo(
        experiment(
            arms,
            runs,
            episodes,
            seed,
            shield,
            transport,
            out,
            workers,
            token,
            lead,
            shield_config,
            group,
            trace,
            device,
            every,
            deadline,
            update_first,
            reward,
            ddpg,
            shorter,
        )
    )
    if (out / "table.md").exists() and not checkpoint.pending(out):
        typer.echo(f"\nrecords, summary.json, table.md and figure.png in {out}")


@cli.command("report")
def report_command(
    directory: Path,
    episodes: Annotated[
        int | None,
        typer.Option(
            min=1, help="Only each run's first N episodes (runs stopped at different points)."
        ),
    ] = None,
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
    episodes: Annotated[
        int | None,
        typer.Option(
            min=1, help="Only each run's first N episodes (runs stopped at different points)."
        ),
    ] = None,
    blocks: Annotated[
        bool,
        typer.Option(
            help="Also a table per block of 100 episodes, the rows side by side in each cell."
        ),
    ] = False,
    partings: Annotated[
        bool,
        typer.Option(help="Also where each run parts from the same run of the first experiment."),
    ] = False,
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
        [
            sys.executable,
            "-m",
            "app",
            "serve",
            "--port",
            str(port),
            "--data-dir",
            str(data_dir),
            "--fsync",
            "never",
            "--log-level",
            "warning",
        ],
        stdout=log,
        stderr=subprocess.STDOUT,
        preexec_fn=partial(parallel.die_with_parent, os.getpid()),
    )
    try:
        deadline = time.monotonic() + 120  # a first start compiles the core: about a minute
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
    transport: Transport = "ws",
    workers: Annotated[int, typer.Option(min=1)] = max(1, os.cpu_count() or 1),
    lockstep: Annotated[
        bool,
        typer.Option(
            help="Train the runs of each arm together, one batched update for all, the arms in "
            "parallel: on two cores the longest arm then sets the pace, not both arms one "
            "after the other."
        ),
    ] = True,
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
        what = (
            "reporting them without training"
            if done >= total
            else "going on from them, not training them again"
        )
        typer.echo(
            f"{out} already holds {min(done, total)} of {total} episodes: {what}; to "
            f"start afresh, remove {out} or pass another --out"
        )
    with tempfile.TemporaryDirectory(dir=out) as tmp, service(Path(tmp) / "data") as url:
        typer.echo(f"shield service at {url}; {runs} runs x {episodes} episodes per arm")
        text = experiment(
            arms,
            runs,
            episodes,
            seed,
            url,
            transport,
            out,
            workers,
            None,
            "train",
            lockstep=runs if lockstep else 0,
            shorter="; shorter: --runs 1 --episodes 20",
        )
    typer.echo(text)
    typer.echo(f"\nfigure: {out / 'figure.png'}; records and summary.json in {out}")


def main(args: list[str] | None = None) -> None:
    """Run the command line; an error in it is one line naming the option (exit status 2)."""
    try:
        code = cli(args, standalone_mode=False)
    except typer.TyperException as error:
        message = error.format_message()
        if "\n" in message:  # no command given: the message is the help
            typer.echo(message, err=True)
            sys.exit(error.exit_code)
        typer.secho(f"error: {message}", err=True, fg="red")
        sys.exit(error.exit_code)
    sys.exit(code if isinstance(code, int) else 0)


if __name__ == "__main__":
    main()
