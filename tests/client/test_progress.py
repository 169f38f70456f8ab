"""Progress lines for runs whose output goes to a log."""

from __future__ import annotations

import io

from client.experiment.progress import Progress


def test_off_a_terminal_progress_writes_lines_with_the_rate_and_the_time_left() -> None:
    log = io.StringIO()
    with Progress(total=10, done=4, every_s=0.0, stream=log) as progress:
        progress.update(2)
        progress.update(4)
    lines = log.getvalue().splitlines()
    assert lines[0] == "going on from 4 of 10 episodes already recorded"
    assert lines[1].startswith("episodes 6 of 10 (60%), ") and lines[1].endswith(" left")
    assert lines[2].startswith("episodes 10 of 10 (100%), ") and lines[2].endswith(", done")
    assert len(lines) == 4 and lines[3].startswith("episodes 10 of 10 (100%), ")  # the end


def test_progress_waits_between_lines_and_says_nothing_when_nothing_ran() -> None:
    log = io.StringIO()
    with Progress(total=10, every_s=3600.0, stream=log) as progress:
        progress.update(3)
        assert log.getvalue() == ""  # within the hour: no line yet
    assert log.getvalue().startswith("episodes 3 of 10 (30%), ")
    quiet = io.StringIO()
    with Progress(total=10, stream=quiet):
        pass
    assert quiet.getvalue() == ""


def test_a_tick_writes_a_line_once_the_interval_is_up_even_with_no_episode_done() -> None:
    log = io.StringIO()
    with Progress(total=10, every_s=0.0, stream=log) as progress:
        progress.tick()
    assert log.getvalue() == "episodes 0 of 10 (0%), 0.0 a minute, time left unknown yet\n"
    quiet = io.StringIO()
    with Progress(total=10, every_s=3600.0, stream=quiet) as progress:
        progress.tick()
    assert quiet.getvalue() == ""  # within the hour: nothing
