"""``python -m app``: the shield service's commands (``python -m app --help`` lists them).

Every command-line error is one line that names the option at fault (exit status 2); the
options themselves are parsed by pydantic-settings from :class:`app.settings.Settings`.
"""

from __future__ import annotations

import logging
import sys
import tempfile
from typing import NoReturn, TypeVar

import uvicorn
from pydantic import ValidationError
from pydantic_core import ErrorDetails
from pydantic_settings import SettingsError

from app.api.connections import ConnectionLimits, protocols
from app.cluster.placement import PlacementError
from app.core import compiled
from app.main import create_app
from app.settings import ClusterSettings, Settings

HELP = """\
usage: python -m app COMMAND [options]

The e-FSM safety shield as a service.

commands:
  serve      serve the shield over HTTP and WebSocket (127.0.0.1:8000 unless told
             otherwise); every option is also an EFSM_* environment variable:
             python -m app serve --help lists them
  serve-ray  the same service sharded on Ray Serve (the 'ray' extra):
             python -m app serve-ray --help
  warm       compile the core's kernels into their cache and say how long it took
             (about a minute the first time, 40-70 s on 2 cores; the container image
             does it when built, so that the service starts in about a second)
"""
COMMANDS = ("serve", "serve-ray", "warm")
log = logging.getLogger("app")
S = TypeVar("S", bound=Settings)


def main(argv: list[str] | None = None) -> None:
    """Parse the command line (and the EFSM_* environment) and run the command."""
    argv = sys.argv[1:] if argv is None else argv
    if not argv:
        sys.stderr.write(HELP)
        sys.exit(2)
    command, options = argv[0], argv[1:]
    if command in ("-h", "--help"):
        sys.stdout.write(HELP)
    elif command == "warm":
        if options:
            usage_error(f"warm takes no options, not {' '.join(options)!r}")
        logging.basicConfig(level="INFO", format="%(message)s")
        warm_core()
    elif command == "serve-ray":
        serve_ray(options)
    elif command == "serve":
        serve(options)
    else:
        usage_error(f"no command {command!r}: {', '.join(COMMANDS)} (python -m app --help)")


def serve(options: list[str]) -> None:
    """The service in this process, until stopped."""
    settings = parse(Settings, options)
    logging.basicConfig(
        level=settings.log_level.upper(), format="%(asctime)s %(levelname)s %(name)s: %(message)s"
    )
    warm_core()
    http, ws = protocols(
        ConnectionLimits(settings.header_timeout, settings.body_timeout, settings.max_connections)
    )
    # a WebSocket frame over the body limit gets an error frame (app/api/routes/stream.py);
    # one over twice the limit is not kept: the stream closes with 1009
    uvicorn.run(
        create_app(settings),
        host=settings.host,
        port=settings.port,
        log_level=settings.log_level,
        http=http,
        ws=ws,
        ws_max_size=2 * settings.max_body_bytes,
        timeout_keep_alive=settings.keep_alive_timeout,
    )


def parse(kind: type[S], options: list[str]) -> S:
    """The settings from ``options`` and the environment, with a data directory this process
    can write; any error is one line naming the option."""
    try:
        settings = kind(_cli_parse_args=options, _cli_exit_on_error=False)
    except SettingsError as error:  # argparse's: an unknown option, a missing value
        usage_error(str(error).removeprefix("error parsing CLI: "))
    except ValidationError as error:
        usage_error("; ".join(describe(e) for e in error.errors()))
    if settings.data_dir is not None:
        try:  # here, not at the first request: the journal must be writable before serving
            settings.data_dir.mkdir(parents=True, exist_ok=True)
            with tempfile.TemporaryFile(dir=settings.data_dir):
                pass
        except OSError as error:
            usage_error(
                f"--data-dir (EFSM_DATA_DIR): cannot write to {settings.data_dir}: {error.strerror}"
            )
    return settings


def describe(error: ErrorDetails) -> str:
    """One settings error as the option and its environment variable, what is wrong and the
    value given."""
    name = str(error["loc"][0]) if error["loc"] else "settings"
    message = error["msg"].removeprefix("Value error, ")
    given = f", not {error['input']!r}" if error["type"] != "value_error" else ""
    return f"--{name.replace('_', '-')} (EFSM_{name.upper()}): {message}{given}"


def usage_error(message: str) -> NoReturn:
    """Say what is wrong with the command line on one line and exit with status 2."""
    sys.stderr.write(f"error: {message}\n")
    sys.exit(2)


def serve_ray(argv: list[str]) -> None:
    """The service sharded on Ray Serve (imported here: Ray is an optional extra)."""
    settings = parse(ClusterSettings, argv)
    logging.basicConfig(
        level=settings.log_level.upper(), format="%(asctime)s %(levelname)s %(name)s: %(message)s"
    )
    try:
        from app.cluster import ray_serve
    except ImportError as error:
        sys.exit(f"serve-ray needs Ray Serve: pip install '.[ray]' ({error})")
    warm_core()  # compiled once here; the shards load the cache
    try:
        ray_serve.run(settings)
    except PlacementError as error:
        sys.exit(str(error))


def warm_core() -> None:
    """Load the compiled core from its cache, compiling what is missing (and saying so)."""
    log.info("loading the compiled core (on a first start it compiles: about a minute)")
    done = compiled.warm()
    if done.compiled:
        log.info(
            "compiled %d kernels in %.1f s; cached for the next start", done.compiled, done.seconds
        )
    else:
        log.info("compiled core loaded from its cache in %.2f s", done.seconds)


if __name__ == "__main__":
    main()
