"""An experiment's runs in worker processes: every (arm, run) in a process of its own, or the
runs of a DDPG arm a lockstep group to a process, with a shared progress count and a deadline."""

from __future__ import annotations

import ctypes
import multiprocessing
import os
import signal
import sys
import time
from collections.abc import Callable
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from functools import partial
from multiprocessing.managers import SyncManager
from pathlib import Path
from typing import Any

from client.experiment.lockstep import run_lockstep
from client.experiment.progress import Progress
from client.experiment.runner import ExperimentConfig, parse_arm, run_one

PR_SET_PDEATHSIG = 1  # prctl(2)


def past(deadline: float) -> bool:
    """Whether the wall clock has passed ``deadline`` (seconds since the epoch)."""
    return time.time() >= deadline


def die_with_parent(parent: int) -> None:
    """A worker (or the progress queue's manager, or the demo's shield service) ends with the
    process that started it, even one killed outright: an orphan would go on appending to
    records that a restarted experiment is writing too, or linger."""
    if sys.platform == "linux":
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(PR_SET_PDEATHSIG, signal.SIGTERM)
        if os.getppid() != parent:  # the parent died before the call
            os._exit(1)


def run_all(
    config: ExperimentConfig,
    out: Path,
    workers: int,
    token: str | None = None,
    bar: Progress | None = None,
    lockstep: int = 0,
    trace: bool = False,
    device: str = "cpu",
    checkpoint_every: float | None = None,
    deadline: float | None = None,
) -> int:
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
                jobs.append(
                    (
                        partial(
                            run_lockstep,
                            indices=group,
                            device=device,
                            checkpoint_every=checkpoint_every,
                            stop=stop,
                        ),
                        (config, arm, out, token),
                    )
                )
        else:
            jobs.extend(
                (partial(run_one, stop=stop), (config, arm, run, out, token))
                for run in range(config.runs)
            )
    context = multiprocessing.get_context("spawn")
    manager = SyncManager(ctx=context)
    manager.start(die_with_parent, (os.getpid(),))
    with (
        manager,
        ProcessPoolExecutor(
            workers, mp_context=context, initializer=die_with_parent, initargs=(os.getpid(),)
        ) as pool,
    ):
        progress = manager.Queue()
        pending: set[Future[int]] = {pool.submit(job, *args, progress, trace) for job, args in jobs}
        appended = 0
        while pending:
            finished, pending = wait(pending, timeout=0.5, return_when=FIRST_COMPLETED)
            while not progress.empty():
                progress.get()
                if bar is not None:
                    bar.update(1)
            if bar is not None:
                bar.tick()
            for future in finished:
                appended += future.result()
        return appended
