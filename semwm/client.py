"""What a robot runs to talk to a semwm service: detections in, clock sync (paper 003, 3.3).

>>> with Client("http://127.0.0.1:8000", token="...") as client:   # doctest: +SKIP
...     client.post_detections([{"time": 12.3, "class": "Cup", "position": [1.0, 2.0]}])
{'applied': 1, 'time': 12.3, 'ignored': 0, 'ignored_detections': []}

>>> sync = ClockSync("http://127.0.0.1:8000", "robot1")       # doctest: +SKIP
>>> sync.exchange()          # one round trip; the service updates its estimate
>>> sync.run(every=3.0)      # a background thread, every third second as in paper 003

:class:`Client` keeps one HTTP/1.1 connection open (keep-alive): a request then
costs one round trip on loopback, not a TCP handshake and a new socket. The robot
keeps stamping its detections with its own clock; the service places them at
``stamp + offset``. The connection (:mod:`semwm.http_connection`) parses answers
with ``httptools``, the C parser uvicorn uses; :func:`http_transport` uses ``urllib``.
"""

from __future__ import annotations

import contextlib
import http.client
import json
import math
import random
import threading
import time
import urllib.parse
import urllib.request
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import orjson

from semwm.collector import collector_paused
from semwm.http_connection import Answer, HttpConnection

Transport = Callable[[str, dict[str, Any]], dict[str, Any]]

_RETRYABLE = (http.client.RemoteDisconnected, ConnectionResetError, BrokenPipeError)
"""What a connection the server closed while it was idle raises on its next use."""


def encode_json(payload: Any) -> bytes:
    """``payload`` as compact JSON: by orjson (a batch of 1,000 detections in 0.1 ms
    against the standard library's 1.2, on the robot's side of every request), numpy
    arrays and scalars included. orjson writes a NaN or an infinity as ``null``, which
    would turn a bad value into an absent one; a body with a ``null`` is made by the
    standard library instead, as is one orjson refuses (an integer beyond 64 bits), so
    the service sees, and refuses, exactly what the robot sent."""
    try:
        body = orjson.dumps(payload, option=orjson.OPT_SERIALIZE_NUMPY)
    except TypeError:
        body = b"null"
    if b"null" not in body:
        return body
    return json.dumps(payload, separators=(",", ":")).encode()


PAUSED_BODY = 64 * 1024
"""Bytes: an answer longer than this is read with Python's cyclic garbage collector
paused (:mod:`semwm.collector`). Its values are thousands of containers, none in a
cycle, and the collections they set off took most of the time: a world of 1,000
objects (346 KB) in 4.4 ms, against 0.8 ms paused, on a 2-core x86_64 box."""


def decode_json(body: bytes) -> Any:
    """``body``'s JSON value: by orjson (a world of 1,000 objects in 0.8 ms, the standard
    library 5.6, on a 2-core x86_64 box; see :data:`PAUSED_BODY`); a body orjson refuses
    (``NaN`` or an infinity, an integer beyond 64 bits, or no JSON at all) by the
    standard library, which reads the first two as it always has and raises its own
    error for the last."""
    if len(body) <= PAUSED_BODY:
        return _decoded(body)
    with collector_paused():  # many containers made, none in a cycle
        return _decoded(body)


def _decoded(body: bytes) -> Any:
    try:
        return orjson.loads(body)
    except orjson.JSONDecodeError:
        return json.loads(body)


class ServiceError(Exception):
    """The service refused a request: ``status`` (4xx/5xx) and its JSON ``body``."""

    def __init__(self, status: int, body: Any) -> None:
        detail = body.get("detail", body) if isinstance(body, dict) else body
        super().__init__(f"HTTP {status}: {detail}")
        self.status = status
        self.body = body


class Client:
    """One keep-alive HTTP/1.1 connection to a semwm service.

    Not thread-safe: give each thread its own client. A connection the service
    closed while idle (after its ``timeout_keep_alive``, 5 s by default) is opened
    again before the next request; a request whose connection dropped is sent again
    once only when that cannot apply it twice (a read, or a write with an
    idempotency key), else the error is raised.

    Parameters
    ----------
    base_url
        The service, e.g. ``http://127.0.0.1:8000``.
    token
        The bearer token (writes need the write token when the service has one).
    timeout
        Seconds to wait for connecting and for each answer.
    idle_reconnect
        Open a new connection when the last one was idle this long (s); keep it below
        the service's keep-alive timeout.
    busy_retries
        An answer 429 or 503 with ``Retry-After`` (the service is behind, or holds
        its limits: nothing was applied) is sent again up to this many times, after
        ``Retry-After`` s times a random factor in [1, 1.5) (jitter: clients told to
        come back together do not all come back at once). 0: raise at once.
    max_wait
        The longest wait one ``Retry-After`` may impose (s).
    rng, sleep
        The jitter's random generator and the wait (tests pass their own).
    """

    def __init__(
        self,
        base_url: str,
        *,
        token: str | None = None,
        timeout: float = 10.0,
        idle_reconnect: float = 4.0,
        busy_retries: int = 3,
        max_wait: float = 30.0,
        rng: random.Random | None = None,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        url = urllib.parse.urlsplit(base_url)
        if url.scheme not in ("http", "https") or not url.hostname:
            raise ValueError(f"base_url must be http(s)://HOST[:PORT]; got {base_url!r}")
        self.host = url.hostname
        self.port = url.port
        self.https = url.scheme == "https"
        self.prefix = url.path.rstrip("/")
        self.timeout = timeout
        self.idle_reconnect = idle_reconnect
        self.busy_retries = busy_retries
        self.max_wait = max_wait
        self._rng = rng or random.Random()
        self._sleep = sleep
        self.waited = 0.0
        """Seconds waited on ``Retry-After`` answers so far."""
        self.headers = {"content-type": "application/json", "accept": "application/json"}
        if token is not None:
            self.headers["authorization"] = f"Bearer {token}"
        self._connection: HttpConnection | None = None
        self._last_used = 0.0
        self.last_headers: dict[str, str] = {}
        """The headers of the last answer (lower-case names), e.g. ``x-semwm-commit``."""

    def _connect(self) -> HttpConnection:
        now = time.monotonic()
        if self._connection is not None and now - self._last_used > self.idle_reconnect:
            self.close()
        if self._connection is None:
            self._connection = HttpConnection(
                self.host, self.port, https=self.https, timeout=self.timeout
            )
        return self._connection

    def request(
        self,
        method: str,
        path: str,
        payload: Any = None,
        *,
        headers: Mapping[str, str] | None = None,
        retry: bool | None = None,
    ) -> Any:
        """Send ``payload`` as JSON (``None``: no body); return the JSON answer.

        Raises :class:`ServiceError` for a 4xx/5xx answer. ``retry`` (default: for
        ``GET``): send again once if the connection dropped before an answer.
        """
        body = None if payload is None else encode_json(payload)
        response = self._exchange(method, path, body, headers, retry)
        for _ in range(self.busy_retries):
            wait = self._retry_after(response)
            if wait is None:
                break
            self._sleep(wait)
            self.waited += wait
            response = self._exchange(method, path, body, headers, retry)
        answer = decode_json(response.body) if response.body else None
        if response.status >= 400:
            raise ServiceError(response.status, answer)
        return answer

    def _retry_after(self, response: Answer) -> float | None:
        """The jittered wait a 429/503 answer asks for, ``None`` for any other."""
        if response.status not in (429, 503):
            return None
        value = dict(response.headers).get("retry-after")
        try:
            seconds = float(value) if value is not None else None
        except ValueError:
            return None
        if seconds is None or not math.isfinite(seconds) or seconds < 0.0:
            return None  # absent, an HTTP date or nonsense: no wait asked for
        return min(seconds, self.max_wait) * (1.0 + 0.5 * self._rng.random())

    def get_text(self, path: str) -> str:
        """``GET path`` answered in text, e.g. ``/metrics`` (Prometheus' format).

        Raises :class:`ServiceError` for a 4xx/5xx answer."""
        response = self._exchange("GET", path, None, {"accept": "text/plain"}, None)
        text = response.body.decode()
        if response.status >= 400:
            raise ServiceError(response.status, text)
        return text

    def _exchange(
        self,
        method: str,
        path: str,
        body: bytes | None,
        headers: Mapping[str, str] | None,
        retry: bool | None,
    ) -> Answer:
        """One request and its answer on the kept connection (see :meth:`request`)."""
        all_headers = {**self.headers, **headers} if headers else self.headers
        again = method == "GET" if retry is None else retry
        for attempt in (1, 2):
            connection = self._connect()
            try:
                response = connection.request(method, self.prefix + path, body, all_headers)
            except _RETRYABLE:
                self.close()
                if attempt == 2 or not again:
                    raise
                continue
            except BaseException:
                self.close()
                raise
            self._last_used = time.monotonic()
            if not response.keep_alive:
                self.close()
            self.last_headers = dict(response.headers)
            return response
        raise AssertionError("unreachable")  # pragma: no cover

    def post_detections(
        self,
        detections: Sequence[Mapping[str, Any]],
        *,
        idempotency_key: str | None = None,
    ) -> dict[str, Any]:
        """``POST /detections`` with one batch, applied whole or not at all.

        Returns ``{"applied", "time", "ignored"}``. With ``idempotency_key`` a request
        whose connection dropped is sent again (the service applies it once).
        """
        headers = {"idempotency-key": idempotency_key} if idempotency_key is not None else None
        answer: dict[str, Any] = self.request(
            "POST",
            "/detections",
            {"detections": list(detections)},
            headers=headers,
            retry=idempotency_key is not None,
        )
        return answer

    def get(self, path: str) -> Any:
        """``GET path`` (e.g. ``/world?class=Cup``): the JSON answer."""
        return self.request("GET", path)

    def close(self) -> None:
        """Close the connection (the next request opens a new one)."""
        if self._connection is not None:
            self._connection.close()
            self._connection = None

    def __enter__(self) -> Client:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def http_transport(base_url: str, timeout: float = 5.0) -> Transport:
    """POST JSON to ``base_url + path`` and return the JSON answer."""

    def post(path: str, payload: dict[str, Any]) -> dict[str, Any]:
        request = urllib.request.Request(
            base_url.rstrip("/") + path,
            data=json.dumps(payload).encode(),
            headers={"content-type": "application/json"},
            method="POST",
        )
        with urllib.request.urlopen(request, timeout=timeout) as response:
            answer: dict[str, Any] = json.loads(response.read())
            return answer

    return post


class ClockSync:
    """Sync exchanges of one source with the service.

    Parameters
    ----------
    base_url
        The service, e.g. ``http://127.0.0.1:8000``.
    source
        The source name its detections carry (``"source": "robot1"``).
    clock
        The robot's clock, the one its detection stamps come from (s).
    transport
        How a JSON body is posted (tests wrap :func:`http_transport`).
    """

    def __init__(
        self,
        base_url: str,
        source: str,
        *,
        clock: Callable[[], float] = time.time,
        transport: Transport | None = None,
    ) -> None:
        self.source = source
        self.clock = clock
        self._post = transport or http_transport(base_url)
        self._path = f"/sources/{urllib.parse.quote(source, safe='')}/sync"
        self.last: dict[str, Any] | None = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def exchange(self) -> dict[str, Any]:
        """One round trip, then report it; returns the service's view of this source."""
        sent = self.clock()
        reply = self._post(self._path, {"sent": sent})
        returned = self.clock()
        finished = {
            "sent": sent,
            "received": reply["received"],
            "replied": reply["replied"],
            "returned": returned,
        }
        self.last = self._post(self._path, finished)
        return self.last

    def sync(self, count: int = 5, interval: float = 0.0) -> dict[str, Any]:
        """``count`` exchanges ``interval`` s apart; returns the last answer."""
        if count < 1:
            raise ValueError(f"count must be at least 1; got {count}")
        answer: dict[str, Any] = {}
        for i in range(count):
            if i and interval > 0:
                time.sleep(interval)
            answer = self.exchange()
        return answer

    @property
    def offset(self) -> float | None:
        """Service clock minus this robot's clock, as the service last estimated it (s)."""
        if self.last is None:
            return None
        offset = self.last.get("clock_offset")
        return float(offset) if offset is not None else None

    def run(self, every: float = 3.0) -> None:
        """Exchange every ``every`` s in a daemon thread until :meth:`stop`; errors
        (service away) are retried at the next tick."""
        if self._thread is not None:
            raise RuntimeError("already running")
        self._stop.clear()

        def loop() -> None:
            while not self._stop.is_set():
                with contextlib.suppress(OSError):  # service away: retry at the next tick
                    self.exchange()
                self._stop.wait(every)

        self._thread = threading.Thread(target=loop, name=f"clock-sync-{self.source}", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
            self._thread = None
