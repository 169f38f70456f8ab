"""``python -m app serve [--host ...] [--port ...] [--data-dir ...] ...``: run the shield."""

from __future__ import annotations

import logging
import sys

import uvicorn

from app.main import create_app
from app.settings import Settings

USAGE = "usage: python -m app serve [--help] [options]"


def main(argv: list[str] | None = None) -> None:
    """Parse the command line (and the EFSM_* environment) and serve until stopped."""
    argv = sys.argv[1:] if argv is None else argv
    if not argv or argv[0] != "serve":
        sys.exit(USAGE)
    settings = Settings(_cli_parse_args=argv[1:])
    logging.basicConfig(level=settings.log_level.upper(),
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    # a WebSocket frame over the body limit gets an error frame (app/api/routes/stream.py);
    # one over twice the limit is not read at all: the connection closes (1009)
    uvicorn.run(create_app(settings), host=settings.host, port=settings.port,
                log_level=settings.log_level, ws_max_size=2 * settings.max_body_bytes)


if __name__ == "__main__":
    main()
