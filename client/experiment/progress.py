"""Progress of a long run: a bar on a terminal, a line now and then in a log.

A run of the paper's protocol takes hours and mostly runs with its output in a file, where a
progress bar shows nothing until the end. Off a terminal, :class:`Progress` writes a line every
``every_s`` seconds instead, with the recent rate and an estimate of the time left.
"""

from __future__ import annotations

import sys
import time
from types import TracebackType
from typing import TextIO

from tqdm import tqdm


class Progress:
    """Counts finished episodes out of ``total`` (``done`` of them before this start)."""

    def __init__(
        self, total: int, done: int = 0, every_s: float = 60.0, stream: TextIO | None = None
    ) -> None:
        self.total, self.done, self.every_s = total, done, every_s
        self.stream = stream or sys.stderr
        self._bar = (
            tqdm(total=total, initial=done, desc="episodes", unit="ep", file=self.stream)
            if self.stream.isatty()
            else None
        )
        self._last = time.monotonic()
        self._last_done = done
        self._first = done

    def update(self, n: int = 1) -> None:
        """``n`` more episodes finished."""
        self.done += n
        if self._bar is not None:
            self._bar.update(n)
        elif time.monotonic() - self._last >= self.every_s:
            self._line()

    def tick(self) -> None:
        """Time passed, whether or not an episode finished: the bar's clock moves on a
        terminal, and off one a line comes once ``every_s`` is up, so that a run whose
        episodes take minutes (its first ones compile the core) still says where it stands."""
        if self._bar is not None:
            self._bar.refresh()
        elif time.monotonic() - self._last >= self.every_s:
            self._line()

    def line(self) -> str:
        """Where the run stands: done of total, the rate since the previous line and the time
        left at that rate (episodes grow longer as a controller learns to survive, so the rate
        of the last minute says more than the rate since the start)."""
        elapsed = time.monotonic() - self._last
        rate = (self.done - self._last_done) / elapsed * 60 if elapsed > 0 else 0.0
        left = self.total - self.done
        if not left:
            eta = "done"
        elif rate > 0:
            eta = f"about {_duration(left / rate * 60)} left"
        else:
            eta = "time left unknown yet"
        return (
            f"episodes {self.done:,} of {self.total:,} ({100 * self.done / self.total:.0f}%), "
            f"{rate:.1f} a minute, {eta}"
        )

    def _line(self) -> None:
        print(self.line(), file=self.stream, flush=True)
        self._last, self._last_done = time.monotonic(), self.done

    def __enter__(self) -> Progress:
        if self._bar is None and 0 < self._first < self.total:
            print(
                f"going on from {self._first:,} of {self.total:,} episodes already recorded",
                file=self.stream,
                flush=True,
            )
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        trace: TracebackType | None,
    ) -> None:
        if self._bar is not None:
            self._bar.close()
        elif self.done > self._first:
            self._line()


def _duration(seconds: float) -> str:
    minutes = round(seconds / 60)
    if minutes < 60:
        return f"{max(minutes, 1)} min"
    return f"{minutes // 60} h {minutes % 60:02d} min"
