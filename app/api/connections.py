"""uvicorn's HTTP and WebSocket protocols with the connection limits of docs/api.md.

uvicorn closes a kept-alive connection that stays idle, but waits for ever on a request whose
line and headers, or body, never finish arriving (a slowloris holds a socket and a file each),
and it has no limit on open connections that a half-sent request cannot pass. Here:

* the request line and headers must arrive within ``header_timeout`` seconds of the
  connection's opening or of the first byte of the request, and take at most
  :data:`MAX_HEADER_BYTES` (else 431 ``headers_too_large``; httptools keeps any amount until the
  headers end, 1 MiB of them were served); a body may pause at most
  ``body_timeout`` seconds between two reads (nginx's ``client_header_timeout`` and
  ``client_body_timeout``); past either, 408 ``request_timeout`` and the connection closes;
* a connection that would be one more than ``max_connections`` open (HTTP and WebSocket) is
  answered 503 ``overloaded`` and closed before it is read;
* a request the HTTP parser cannot read gets 400 ``bad_request`` with the service's error body;
* a WebSocket frame over ``ws_max_size`` is refused with the close code 1009 that the client
  can read: the rest of the frame is read and dropped until the client closes, or for at most
  the protocol's close time-out, instead of a close with unread data, which resets the
  connection and loses the close frame.

:func:`protocols` builds the two classes for ``uvicorn.run(http=..., ws=...)``.
"""

from __future__ import annotations

import asyncio
import json
import logging
from collections.abc import Callable
from dataclasses import dataclass
from http import HTTPStatus
from typing import ClassVar

from uvicorn.protocols.http.httptools_impl import HttpToolsProtocol
from uvicorn.protocols.websockets.websockets_sansio_impl import WebSocketsSansIOProtocol

from app.api.errors import error_body

log = logging.getLogger("app.api")
MAX_HEADER_BYTES = 64 * 1024  # [bytes] a request line and its headers (nginx: 4 x 8 KiB)
LINGER = 2.0  # [s] a refused connection is read and dropped so long for its answer to arrive


@dataclass(frozen=True)
class ConnectionLimits:
    """What one connection may take of the server."""

    header_timeout: float  # [s] from the opening, or a request's first byte, to its headers
    body_timeout: float  # [s] the longest pause between two reads of a body
    max_connections: int  # open at once, HTTP and WebSocket


class LimitedHttp(HttpToolsProtocol):
    """uvicorn's HTTP/1.1 protocol (httptools) with read time-outs and a connection limit."""

    limits: ClassVar[ConnectionLimits]
    _timer: asyncio.TimerHandle | None = None
    _header_bytes: int | None = None  # of the request line and headers read; None: not in them
    _refused = False  # answered: what else arrives is dropped until the client or LINGER ends

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        super().connection_made(transport)
        if len(self.connections) > self.limits.max_connections:
            log.debug(
                "refused a connection from %s: %d open", self.client, len(self.connections) - 1
            )
            self._answer(
                HTTPStatus.SERVICE_UNAVAILABLE,
                "overloaded",
                f"the server has its most connections open "
                f"({self.limits.max_connections}); try again shortly",
            )
            return
        self._header_bytes = 0
        self._arm(self.limits.header_timeout, self._headers_late)

    def data_received(self, data: bytes) -> None:
        if self._refused:
            return
        in_headers = self._header_bytes is not None
        super().data_received(data)
        if in_headers and self._header_bytes is not None:  # the whole chunk: header bytes
            self._header_bytes += len(data)
            if self._header_bytes > MAX_HEADER_BYTES:
                self._answer(
                    HTTPStatus.REQUEST_HEADER_FIELDS_TOO_LARGE,
                    "headers_too_large",
                    f"the request line and headers take over {MAX_HEADER_BYTES} bytes",
                )

    def connection_lost(self, exc: Exception | None) -> None:
        self._disarm()
        super().connection_lost(exc)

    def on_message_begin(self) -> None:
        super().on_message_begin()
        if self._timer is None:  # the next request of a kept-alive connection
            self._header_bytes = 0
            self._arm(self.limits.header_timeout, self._headers_late)

    def on_headers_complete(self) -> None:
        self._header_bytes = None
        self._disarm()
        super().on_headers_complete()
        if not (self.parser.should_upgrade() and self._should_upgrade()):
            self._arm(self.limits.body_timeout, self._body_late)

    def on_body(self, body: bytes) -> None:
        super().on_body(body)
        self._arm(self.limits.body_timeout, self._body_late)

    def on_message_complete(self) -> None:
        self._disarm()
        super().on_message_complete()

    def send_400_response(self, msg: str) -> None:
        self._answer(HTTPStatus.BAD_REQUEST, "bad_request", msg)

    def _headers_late(self) -> None:
        self._timer = None
        log.debug(
            "closed a connection from %s: no complete headers within %s s",
            self.client,
            self.limits.header_timeout,
        )
        self._answer(
            HTTPStatus.REQUEST_TIMEOUT,
            "request_timeout",
            f"the request line and headers took over {self.limits.header_timeout} s",
        )

    def _body_late(self) -> None:
        self._timer = None
        if self.flow.read_paused:  # the server is behind, not the client: wait on
            self._arm(self.limits.body_timeout, self._body_late)
            return
        log.debug(
            "closed a connection from %s: its body paused over %s s",
            self.client,
            self.limits.body_timeout,
        )
        cycle = self.cycle
        if cycle.response_started:
            self.transport.close()
            return
        # the request's task reads a disconnect and its answer goes nowhere
        cycle.disconnected = True
        cycle.message_event.set()
        self._answer(
            HTTPStatus.REQUEST_TIMEOUT,
            "request_timeout",
            f"the request body paused over {self.limits.body_timeout} s",
        )

    def _answer(self, status: HTTPStatus, code: str, message: str) -> None:
        """Write a whole response with the service's error body and end the connection: the
        response and its end go out, and whatever the client still sends is read and dropped
        for at most :data:`LINGER` (a close with unread data would reset the connection and
        lose the answer)."""
        if self.transport.is_closing() or self._refused:
            return
        self._refused = True
        body = json.dumps(error_body(code, message)).encode()
        head = [f"HTTP/1.1 {status.value} {status.phrase}".encode()]
        head += [name + b": " + value for name, value in self.server_state.default_headers]
        head += [
            b"content-type: application/json",
            b"content-length: %d" % len(body),
            b"connection: close",
        ]
        self.transport.write(b"\r\n".join(head) + b"\r\n\r\n" + body)
        self.transport.write_eof()
        self._arm(LINGER, self.transport.close)

    def _arm(self, seconds: float, then: Callable[[], None]) -> None:
        self._disarm()
        self._timer = self.loop.call_later(seconds, then)

    def _disarm(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None


class LingeringWebSocket(WebSocketsSansIOProtocol):
    """uvicorn's WebSocket protocol (websockets, Sans-I/O) whose refusal of a frame too large
    reaches the client: the close frame goes out, then incoming data is dropped until the
    client closes (it reads the close once its frame is sent) or the close time-out."""

    def handle_parser_exception(self) -> None:
        if self.close_sent:  # the rest of the refused frame: dropped by the parser
            return
        assert self.conn.close_sent is not None
        self.queue.put_nowait(
            {
                "type": "websocket.disconnect",
                "code": self.conn.close_sent.code,
                "reason": self.conn.close_sent.reason,
            }
        )
        self.transport.write(b"".join(self.conn.data_to_send()))
        self.close_sent = True
        self.close_timer = self.loop.call_later(self.close_timeout, self.transport.close)


def protocols(limits: ConnectionLimits) -> tuple[type[LimitedHttp], type[LingeringWebSocket]]:
    """The HTTP and WebSocket protocol classes for ``uvicorn.run``, bound to ``limits``."""

    class Http(LimitedHttp):
        pass

    Http.limits = limits
    return Http, LingeringWebSocket
