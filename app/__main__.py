"""``python -m app serve [--host ...] [--port ...] [--data-dir ...] ...``: run the shield.

``python -m app serve-ray --shards N ...`` runs it sharded on Ray Serve (the ``ray`` extra).

``python -m app warm`` compiles the core's kernels into their cache and says how long it took
(the image build runs it, so that a container starts in about a second).
"""

from __future__ import annotations

import logging
import sys

import uvicorn

from app.cluster.placement import PlacementError
from app.core import compiled
from app.main import create_app
from app.settings import ClusterSettings, Settings

USAGE = ("usage: python -m app serve [--help] [options]  |  python -m app serve-ray [--help] "
         "[options]  |  python -m app warm")
log = logging.getLogger("app")


def main(argv: list[str] | None = None) -> None:
    """Parse the command line (and the EFSM_* environment) and serve until stopped."""
    argv = sys.argv[1:] if argv is None else argv
    if argv == ["warm"]:
        logging.basicConfig(level="INFO", format="%(message)s")
        warm_core()
        return
    if argv and argv[0] == "serve-ray":
        serve_ray(argv[1:])
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


def serve_ray(argv: list[str]) -> None:
    """The service sharded on Ray Serve (imported here: Ray is an optional extra)."""
    settings = ClusterSettings(_cli_parse_args=argv)
    logging.basicConfig(level=settings.log_level.upper(),
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
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
    log.info("loading the compiled core (on a first start it compiles: about 15 s)")
    done = compiled.warm()
    if done.compiled:
        log.info("compiled %d kernels in %.1f s; cached for the next start", done.compiled,
                 done.seconds)
    else:
        log.info("compiled core loaded from its cache in %.2f s", done.seconds)


if __name__ == "__main__":
    main()
