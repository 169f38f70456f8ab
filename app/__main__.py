"""``python -m app serve [--host ...] [--port ...] [--data-dir ...] ...``: run the shield.

``python -m app warm`` compiles the core's kernels into their cache and says how long it took
(the image build runs it, so that a container starts in about a second).
"""

from __future__ import annotations

import logging
import sys

import uvicorn

from app.core import compiled
from app.main import create_app
from app.settings import Settings

USAGE = "usage: python -m app serve [--help] [options]  |  python -m app warm"
log = logging.getLogger("app")


def main(argv: list[str] | None = None) -> None:
    """Parse the command line (and the EFSM_* environment) and serve until stopped."""
    argv = sys.argv[1:] if argv is None else argv
    if argv == ["warm"]:
        logging.basicConfig(level="INFO", format="%(message)s")
        warm_core()
        return
    if not argv or argv[0] != "serve":
        sys.exit(USAGE)
    settings = Settings(_cli_parse_args=argv[1:])
    logging.basicConfig(level=settings.log_level.upper(),
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    warm_core()
    # a WebSocket frame over the body limit gets an error frame (app/api/routes/stream.py);
    # one over twice the limit is not read at all: the connection closes (1009)
    uvicorn.run(create_app(settings), host=settings.host, port=settings.port,
                log_level=settings.log_level, ws_max_size=2 * settings.max_body_bytes)


def warm_core() -> None:
    """Load the compiled core from its cache, compiling what is missing (and saying so)."""
    log.info("loading the compiled core (on a first start it compiles: about 15 s)")
    done = compiled.warm()
    if done.compiled:
        log.info("compiled %d kernels in %.1f s; cached for the next start", done.compiled,
                 done.seconds)
    else:
        log.info("compiled core loaded from its cache in %.2f s", done.seconds)


if __name__ == "__main__":
    main()
