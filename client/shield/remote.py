"""Clients of the shield's HTTP and WebSocket API, with the same method names everywhere.

    with ShieldClient("http://127.0.0.1:8000", token="...") as shield:
        decision = shield.revise([14.2, 38.5, 15.0], 0.8, stream="car-1")

Decisions come back as :class:`app.core.Decision`, the very type the in-process shield returns.
An error body raises :class:`ShieldAPIError` (status, code, message, field); a server that
cannot be reached raises :class:`ShieldUnavailable`. With ``retry=Retry()``, every step gets an
idempotency key and is sent again when its answer does not come (:mod:`client.shield.retry`):
the service applies it once.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor, wait
from http import HTTPStatus
from typing import Any

import httpx
import websocket

from app.core import Decision
from client.shield.retry import Retry, call_with_retry, call_with_retry_async, keyed

DEFAULT_TIMEOUT = 10.0  # [s]


class ShieldAPIError(Exception):
    """The service answered with an error body."""

    def __init__(self, status: int, code: str, message: str, field: str | None) -> None:
        super().__init__(f"{status} {code}: {message}" + (f" (field {field})" if field else ""))
        self.status, self.code, self.message, self.field = status, code, message, field


class ShieldUnavailable(Exception):
    """The service could not be reached."""


def worth_retrying(error: Exception) -> bool:
    """Whether a step that failed so may succeed if sent again: no answer came, or the service
    was unavailable for the moment (503, except a model set aside for damaged files)."""
    if isinstance(error, ShieldUnavailable):
        return True
    return (
        isinstance(error, ShieldAPIError)
        and error.status == 503
        and error.code != "model_quarantined"
    )


def step_body(observation: Sequence[float], action: float | None, **options: Any) -> dict[str, Any]:
    """A step's JSON body; options with their default value are left out."""
    body: dict[str, Any] = {
        "observation": [float(v) for v in observation],
        "action": None if action is None else float(action),
    }
    defaults = {
        "stream": "0",
        "event": None,
        "done": False,
        "applied_action": None,
        "learn": True,
        "shadow": False,
        "idempotency_key": None,
    }
    for key, value in options.items():
        if key not in defaults:
            raise TypeError(f"unknown step option {key!r}")
        if value != defaults[key]:
            body[key] = value
    return body


def _raise_for(response: httpx.Response) -> None:
    if response.is_success:
        return
    try:
        error = response.json()["error"]
    except (ValueError, KeyError, TypeError):
        text = response.text[:200]
        raise ShieldAPIError(response.status_code, "http_error", text, None) from None
    raise ShieldAPIError(response.status_code, error["code"], error["message"], error.get("field"))


def _auth(token: str | None) -> dict[str, str]:
    return {"Authorization": f"Bearer {token}"} if token else {}


class StepRequests:
    """The requests of the per-step routes, built from what the client fixed once (URLs and
    headers; ``send`` adds the client's timeout): httpx's general request building (merging
    URLs, headers and cookies) costs about 0.3 ms a request on a 2-core machine, about a
    model's step."""

    def __init__(self, http: httpx.Client | httpx.AsyncClient, model: str | None) -> None:
        base = str(http.base_url).rstrip("/") + ("" if model is None else f"/models/{model}")
        self._revise = httpx.URL(f"{base}/revise")
        self._batch = httpx.URL(f"{base}/revise/batch")
        self._headers = dict(http.headers)

    def revise(self, body: dict[str, Any]) -> httpx.Request:
        return self._post(self._revise, body)

    def batch(self, steps: Sequence[Mapping[str, Any]]) -> httpx.Request:
        return self._post(self._batch, {"steps": list(steps)})

    def _post(self, url: httpx.URL, body: dict[str, Any]) -> httpx.Request:
        return httpx.Request("POST", url, json=body, headers=self._headers)


class ShieldClient:
    """Synchronous HTTP client (keep-alive); with ``retry``, steps are keyed and sent again
    when their answer does not come."""

    def __init__(
        self,
        url: str,
        *,
        token: str | None = None,
        model: str | None = None,
        timeout: float = DEFAULT_TIMEOUT,
        retry: Retry | None = None,
    ) -> None:
        self.model = model
        self.retry = retry
        self._http = httpx.Client(base_url=url, headers=_auth(token), timeout=timeout)
        self._steps = StepRequests(self._http, model)

    def _step(self, request: Callable[[], httpx.Request]) -> Any:
        if self.retry is None:
            return self._send(request())
        return call_with_retry(lambda: self._send(request()), self.retry, worth_retrying)

    def _call(self, method: str, path: str, **kwargs: Any) -> Any:
        return self._send(self._http.build_request(method, path, **kwargs))

    def _send(self, request: httpx.Request) -> Any:
        try:
            response = self._http.send(request)
        except httpx.TransportError as error:
            raise ShieldUnavailable(
                f"shield at {self._http.base_url} unreachable: {error}"
            ) from error
        _raise_for(response)
        return response.json() if response.content else None

    def revise(
        self, observation: Sequence[float], action: float | None, **options: Any
    ) -> Decision:
        """One step; options are the API's (stream, event, done, applied_action, learn,
        idempotency_key, ...)."""
        body = step_body(observation, action, **options)
        if self.retry is not None:
            body = keyed(body)
        return Decision.from_dict(self._step(lambda: self._steps.revise(body)))

    def revise_batch(self, steps: Sequence[Mapping[str, Any]]) -> list[Decision]:
        """Steps in order (each a step body; with a ``model`` key when no model is set)."""
        if self.retry is not None:
            steps = [keyed(s) for s in steps]
        result = self._step(lambda: self._steps.batch(steps))
        return [Decision.from_dict(d) for d in result["decisions"]]

    def snapshot(self, name: str | None = None, **query: Any) -> dict[str, Any]:
        """GET /models/{name} (tpm=..., action=..., exact=...)."""
        result: dict[str, Any] = self._call(
            "GET", f"/models/{name or self.model or 'default'}", params=query
        )
        return result

    def restore(self, name: str, snapshot: Mapping[str, Any]) -> dict[str, Any]:
        result: dict[str, Any] = self._call("PUT", f"/models/{name}", json=snapshot)
        return result

    def models(self) -> list[dict[str, Any]]:
        result: list[dict[str, Any]] = self._call("GET", "/models")["models"]
        return result

    def create_model(self, name: str, config: Mapping[str, Any] | None = None) -> dict[str, Any]:
        result: dict[str, Any] = self._call(
            "POST", "/models", json={"name": name, "config": dict(config or {})}
        )
        return result

    def delete_model(self, name: str) -> None:
        self._call("DELETE", f"/models/{name}")

    def reset_model(self, name: str) -> dict[str, Any]:
        result: dict[str, Any] = self._call("POST", f"/models/{name}/reset")
        return result

    def health(self) -> bool:
        return bool(self._call("GET", "/healthz")["status"] == "ok")

    def close(self) -> None:
        self._http.close()

    def __enter__(self) -> ShieldClient:
        return self

    def __exit__(self, *_: object) -> None:
        self.close()


class AsyncShieldClient:
    """Asynchronous HTTP client with the same methods, as coroutines."""

    def __init__(
        self,
        url: str,
        *,
        token: str | None = None,
        model: str | None = None,
        timeout: float = DEFAULT_TIMEOUT,
        retry: Retry | None = None,
    ) -> None:
        self.model = model
        self.retry = retry
        self._http = httpx.AsyncClient(base_url=url, headers=_auth(token), timeout=timeout)
        self._steps = StepRequests(self._http, model)

    async def _step(self, request: Callable[[], httpx.Request]) -> Any:
        if self.retry is None:
            return await self._send(request())
        return await call_with_retry_async(
            lambda: self._send(request()), self.retry, worth_retrying
        )

    async def _call(self, method: str, path: str, **kwargs: Any) -> Any:
        return await self._send(self._http.build_request(method, path, **kwargs))

    async def _send(self, request: httpx.Request) -> Any:
        try:
            response = await self._http.send(request)
        except httpx.TransportError as error:
            raise ShieldUnavailable(
                f"shield at {self._http.base_url} unreachable: {error}"
            ) from error
        _raise_for(response)
        return response.json() if response.content else None

    async def revise(
        self, observation: Sequence[float], action: float | None, **options: Any
    ) -> Decision:
        body = step_body(observation, action, **options)
        if self.retry is not None:
            body = keyed(body)
        return Decision.from_dict(await self._step(lambda: self._steps.revise(body)))

    async def revise_batch(self, steps: Sequence[Mapping[str, Any]]) -> list[Decision]:
        if self.retry is not None:
            steps = [keyed(s) for s in steps]
        result = await self._step(lambda: self._steps.batch(steps))
        return [Decision.from_dict(d) for d in result["decisions"]]

    async def snapshot(self, name: str | None = None, **query: Any) -> dict[str, Any]:
        result: dict[str, Any] = await self._call(
            "GET", f"/models/{name or self.model or 'default'}", params=query
        )
        return result

    async def models(self) -> list[dict[str, Any]]:
        result: list[dict[str, Any]] = (await self._call("GET", "/models"))["models"]
        return result

    async def create_model(
        self, name: str, config: Mapping[str, Any] | None = None
    ) -> dict[str, Any]:
        result: dict[str, Any] = await self._call(
            "POST", "/models", json={"name": name, "config": dict(config or {})}
        )
        return result

    async def delete_model(self, name: str) -> None:
        await self._call("DELETE", f"/models/{name}")

    async def health(self) -> bool:
        return bool((await self._call("GET", "/healthz"))["status"] == "ok")

    async def close(self) -> None:
        await self._http.aclose()

    async def __aenter__(self) -> AsyncShieldClient:
        return self

    async def __aexit__(self, *_: object) -> None:
        await self.close()


class BatchShield:
    """Steps over the batch route across models: one request per step here, or one request for
    a step of every model with :meth:`revise_many` (lockstep training of several runs)."""

    def __init__(
        self,
        url: str,
        *,
        token: str | None = None,
        model: str = "default",
        timeout: float = DEFAULT_TIMEOUT,
    ) -> None:
        self.model = model
        self._client = ShieldClient(url, token=token, timeout=timeout)

    def revise(
        self, observation: Sequence[float], action: float | None, **options: Any
    ) -> Decision:
        return self.revise_many([(self.model, step_body(observation, action, **options))])[0]

    def revise_many(self, steps: Sequence[tuple[str, dict[str, Any]]]) -> list[Decision]:
        """``(model, step body)`` pairs, applied in order in one request."""
        return self._client.revise_batch([{**body, "model": model} for model, body in steps])

    @staticmethod
    def revise_across(
        rounds: Sequence[tuple[BatchShield, Sequence[tuple[str, dict[str, Any]]]]],
        pool: ThreadPoolExecutor,
    ) -> list[list[Decision]]:
        """One :meth:`revise_many` request per shield (each on a service of its own), all in
        flight at once on ``pool``'s threads, so the services work at the same time; the
        answers in the order of ``rounds``, the first error raised after all have come back."""
        futures = [pool.submit(shield.revise_many, steps) for shield, steps in rounds]
        wait(futures)
        return [f.result() for f in futures]

    def close(self) -> None:
        self._client.close()


class ShieldSession:
    """One WebSocket connection: each step one frame, replies in order. With ``retry``, steps
    are keyed, and a lost session is opened again and its unanswered steps sent again.

    Frames are read on the calling thread (websocket-client), with no reader thread of its own
    to hand them over: a training loop that asks for every action waits for nothing else.
    """

    def __init__(
        self,
        url: str,
        *,
        token: str | None = None,
        model: str | None = None,
        timeout: float = DEFAULT_TIMEOUT,
        retry: Retry | None = None,
    ) -> None:
        ws_url = url.replace("http://", "ws://", 1).replace("https://", "wss://", 1)
        self._url = ws_url.rstrip("/") + ("/ws" if model is None else f"/models/{model}/ws")
        self._header = [f"Authorization: Bearer {token}"] if token else None
        self._timeout = timeout
        self.retry = retry
        self._ws = self._connect()
        self._lost = False  # the connection broke: open another before the next send

    def _connect(self) -> websocket.WebSocket:
        ws_url, header = self._url, self._header
        try:
            # replies are decoded strictly as UTF-8 by recv(); the library's own byte-by-byte
            # check in Python would cost more than the step
            return websocket.create_connection(
                ws_url, timeout=self._timeout, header=header, skip_utf8_validation=True
            )
        except websocket.WebSocketBadStatusException as error:
            if error.status_code == HTTPStatus.FORBIDDEN:  # refused before the handshake
                raise ShieldAPIError(
                    error.status_code, "unauthorized", "missing or wrong bearer token", None
                ) from error
            raise ShieldUnavailable(f"shield at {ws_url} refused the session: {error}") from error
        except (OSError, websocket.WebSocketException) as error:
            raise ShieldUnavailable(f"shield at {ws_url} unreachable: {error}") from error

    def _send(self, text: str) -> None:
        try:
            self._ws.send(text)
        except (OSError, websocket.WebSocketException) as error:
            raise ShieldUnavailable(f"WebSocket session lost: {error}") from error

    def _receive(self) -> dict[str, Any]:
        try:
            reply: dict[str, Any] = json.loads(self._ws.recv())
        except (OSError, websocket.WebSocketException, ValueError) as error:
            raise ShieldUnavailable(f"WebSocket session lost: {error}") from error
        return reply

    @staticmethod
    def _decision(reply: dict[str, Any]) -> Decision:
        if "error" in reply:
            e = reply["error"]
            status = {
                "unknown_model": 404,
                "too_large": 413,
                "model_quarantined": 503,
                "shard_unavailable": 503,
            }.get(e["code"], 422)
            raise ShieldAPIError(status, e["code"], e["message"], e.get("field"))
        return Decision.from_dict(reply)

    def revise(
        self, observation: Sequence[float], action: float | None, **options: Any
    ) -> Decision:
        body = step_body(observation, action, **options)
        if self.retry is None:
            self._send(json.dumps(body))
            return self._decision(self._receive())
        return self._exchange([keyed(body)])[0]

    def revise_batch(self, steps: Sequence[Mapping[str, Any]]) -> list[Decision]:
        """Send every step, then read every reply (pipelined, in order); errors are raised
        after all replies are read, so the session stays in step."""
        if self.retry is not None:
            return self._exchange([keyed(s) for s in steps])
        for step in steps:
            self._send(json.dumps(step))
        replies = [self._receive() for _ in steps]
        return [self._decision(r) for r in replies]

    def _exchange(self, steps: Sequence[Mapping[str, Any]]) -> list[Decision]:
        """Keyed steps sent and answered under :attr:`retry`: a lost session is opened again
        and every step sent again (those applied already are answered, not applied again)."""
        assert self.retry is not None
        texts = [json.dumps(s) for s in steps]

        def send() -> list[Decision]:
            if self._lost:
                self._ws = self._connect()
                self._lost = False
            try:
                for text in texts:
                    self._send(text)
                replies = [self._receive() for _ in texts]
            except ShieldUnavailable:
                self._ws.close()
                self._lost = True
                raise
            return [self._decision(r) for r in replies]

        return call_with_retry(send, self.retry, worth_retrying)

    @staticmethod
    def revise_across(steps: Sequence[tuple[ShieldSession, Mapping[str, Any]]]) -> list[Decision]:
        """``(session, step body)`` pairs: every step is sent before any reply is read, so
        services behind different sessions work at the same time (lockstep runs with a sidecar
        each); replies come back in order, errors after all are read."""
        for session, step in steps:
            session._send(json.dumps(step))
        replies = [session._receive() for session, _ in steps]
        return [ShieldSession._decision(r) for r in replies]

    def close(self) -> None:
        self._ws.close()

    def __enter__(self) -> ShieldSession:
        return self

    def __exit__(self, *_: object) -> None:
        self.close()
