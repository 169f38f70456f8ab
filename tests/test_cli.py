"""``python -m app`` as a user meets it: the help lists every command, and every error on the
command line is one line that names the option at fault, with exit status 2 and no traceback."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow  # each test starts a process that imports the service


def app(*args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "app", *args], capture_output=True, text=True, timeout=120, env=env
    )


def test_the_help_lists_every_command() -> None:
    done = app("--help")
    assert done.returncode == 0, done.stderr
    for command in ("serve", "serve-ray", "warm"):
        assert f"\n  {command} " in done.stdout
    assert "python -m app serve --help" in done.stdout
    assert app("-h").stdout == done.stdout


def test_serve_help_lists_every_option() -> None:
    done = app("serve", "--help")
    assert done.returncode == 0, done.stderr
    for option in ("--port", "--data-dir", "--config", "--token", "--fsync"):
        assert option in done.stdout


def test_no_command_prints_the_help_and_fails() -> None:
    done = app()
    assert done.returncode == 2 and "commands:" in done.stderr and not done.stdout


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (
            ("serve", "--port", "abc"),
            "error: --port (EFSM_PORT): Input should be a valid integer, unable to parse "
            "string as an integer, not 'abc'",
        ),
        (("serve", "--port", "70000"), "--port (EFSM_PORT): Input should be less than or equal"),
        (
            ("serve", "--data-dir", "{tmp}/a-file/models"),
            "error: --data-dir (EFSM_DATA_DIR): cannot write to {tmp}/a-file/models: "
            "Not a directory",
        ),
        (
            ("serve", "--config", "{tmp}/missing.json"),
            "--config (EFSM_CONFIG): Path does not point",
        ),
        (("serve", "--config", "{tmp}/a-file"), "--config (EFSM_CONFIG): {tmp}/a-file: not JSON"),
        (
            ("serve", "--config", "{tmp}/bad.json"),
            "--config (EFSM_CONFIG): {tmp}/bad.json: clustering.epsilon: expected a number",
        ),
        (("serve", "--token", ""), "--token (EFSM_TOKEN): a token that is set must not be empty"),
        (("serve", "--fsync", "sometimes"), "--fsync (EFSM_FSYNC): Input should be 'always'"),
        (("serve", "--bogus", "1"), "error: unrecognized arguments: --bogus 1"),
        (("serve", "--port"), "error: argument --port: expected one argument"),
        (("serve-ray", "--shards", "0"), "--shards (EFSM_SHARDS): Input should be greater than"),
        (("warm", "--now"), "error: warm takes no options, not '--now'"),
        (("start",), "error: no command 'start': serve, serve-ray, warm"),
    ],
)
def test_a_command_line_error_is_one_line_naming_the_option(
    tmp_path: Path, args: tuple[str, ...], message: str
) -> None:
    (tmp_path / "a-file").write_text("not json")
    (tmp_path / "bad.json").write_text('{"clustering": {"epsilon": "wide"}}')
    done = app(*(a.replace("{tmp}", str(tmp_path)) for a in args))
    assert done.returncode == 2
    assert done.stderr.splitlines() == [done.stderr.strip()]  # one line
    assert message.replace("{tmp}", str(tmp_path)) in done.stderr


def test_an_environment_variable_is_named_like_its_option() -> None:
    done = app("serve", env={**os.environ, "EFSM_MAX_BATCH": "none"})
    assert done.returncode == 2
    assert done.stderr.startswith("error: --max-batch (EFSM_MAX_BATCH): Input should be a valid")
