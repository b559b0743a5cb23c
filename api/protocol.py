"""uvicorn's HTTP protocols with a deadline for a request's headers (against slowloris).

uvicorn closes idle keep-alive connections after ``timeout_keep_alive``, but a
connection that never sends anything, or sends its headers one byte at a time, is
kept forever: a few hundred of them fill ``limit_concurrency`` and every real client
gets 503. These protocols give each connection ``timeout_request`` seconds to finish
a request's headers, counted from the connection (first request) or from the end of
the previous response (the next one); a connection that misses it is closed.

The deadline is a mixin over both of uvicorn's HTTP/1.1 implementations: httptools
(a C parser, the faster one, used when installed, as uvicorn's ``auto`` does) and h11
(pure Python). Both set ``self.cycle`` to a new request-response cycle once a
request's headers are complete, and call ``on_response_complete`` when its response
is sent; that is all the mixin relies on.

Issue 30 added three limits, since one client holding 300 connections (idle, slow
headers, slow bodies or streams) kept ``/health`` at 503:

* the deadline covers the whole request, headers and body: a connection whose body is
  still arriving when it runs out is closed too (a request whose body is in is never
  cut, however long its answer takes);
* one client (one peer address) holds at most ``max_per_client`` connections; those
  beyond do not count towards ``limit_concurrency``, get :data:`OVER_CAP_SECONDS` for
  their request, and only a probe is served on them (anything else is 503);
* ``GET /health`` and ``GET /ready`` are served when every slot of
  ``limit_concurrency`` is taken (uvicorn answers every other request 503 then).
"""

from __future__ import annotations

import asyncio
import importlib.util
import logging
from typing import TYPE_CHECKING, Any, Literal

from uvicorn.protocols.http.h11_impl import H11Protocol

HttpImplementation = Literal["auto", "h11", "httptools"]

if TYPE_CHECKING:

    class _UvicornHTTPProtocol(asyncio.Protocol):
        """What the mixin uses of uvicorn's HTTP protocols (for type checking only)."""

        loop: asyncio.AbstractEventLoop
        transport: asyncio.Transport
        connections: set[Any]
        logger: logging.Logger
        cycle: Any

        def on_response_complete(self) -> None: ...

else:
    _UvicornHTTPProtocol = object


class HeaderDeadline(_UvicornHTTPProtocol):
    """Mixin for a uvicorn HTTP protocol: close connections too slow to send headers.

    Put it before the protocol class in the bases (``class P(HeaderDeadline, H11Protocol)``).
    """

    timeout_request = 10.0
    """Seconds a client has to send a request's headers (set per server, see
    :func:`with_header_deadline`)."""

    max_per_client: int | None = None
    """Connections one peer address may hold (set per server)."""
    _clients: dict[str, int] = {}  # noqa: RUF012 - per server: with_header_deadline's class
    _peer: str | None = None
    _over = False  # beyond max_per_client: uncounted, probes only
    _limit: int | None = None
    _deadline: asyncio.TimerHandle | None = None

    @property
    def limit_concurrency(self) -> int | None:
        """uvicorn's limit, read when a request's headers are in: none for the probes."""
        scope = getattr(self, "scope", None)
        if scope is not None and scope.get("method") == "GET" and scope.get("path") in PROBES:
            return None
        return 0 if self._over else self._limit  # 0: uvicorn answers 503

    @limit_concurrency.setter
    def limit_concurrency(self, value: int | None) -> None:
        self._limit = value

    def _arm(self) -> None:
        """Start the clock for the next request's headers."""
        self._disarm()
        waiting_since = self.cycle  # a new request replaces it once its headers are in
        if waiting_since is not None and not waiting_since.response_complete:
            # a pipelined request already in (its headers complete) is being served: its
            # own response re-arms the clock when it is sent
            return
        seconds = self.timeout_request
        if self._over:
            seconds = min(seconds, OVER_CAP_SECONDS)
        self._deadline = self.loop.call_later(seconds, self._too_slow, waiting_since)

    def _disarm(self) -> None:
        if self._deadline is not None:
            self._deadline.cancel()
            self._deadline = None

    def _too_slow(self, waiting_since: object) -> None:
        self._deadline = None
        if self.transport.is_closing():
            return
        cycle = self.cycle
        if cycle is waiting_since:
            self.logger.info("closing a connection that sent no complete request headers in time")
            self.transport.close()
        elif cycle is not None and cycle.more_body:
            self.logger.info("closing a connection whose request body did not arrive in time")
            self.transport.close()

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        super().connection_made(transport)
        peer = transport.get_extra_info("peername")
        self._peer = str(peer[0]) if isinstance(peer, tuple) and peer else ""
        held = self._clients.get(self._peer, 0) + 1
        self._clients[self._peer] = held
        if self.max_per_client is not None and held > self.max_per_client:
            self._over = True
            self.connections.discard(self)  # takes no slot: serves a probe, else 503
        self._arm()

    def on_response_complete(self) -> None:
        super().on_response_complete()
        if not self.transport.is_closing():
            self._arm()

    def connection_lost(self, exc: Exception | None) -> None:
        self._disarm()
        if self._peer is not None:
            left = self._clients.get(self._peer, 1) - 1
            if left > 0:
                self._clients[self._peer] = left
            else:
                self._clients.pop(self._peer, None)
            self._peer = None
        super().connection_lost(exc)


PROBES = frozenset({"/health", "/ready"})
"""Paths served past ``limit_concurrency`` (liveness and readiness must answer)."""
OVER_CAP_SECONDS = 1.0
"""Seconds a connection beyond its client's bound has for a request."""


class HeaderDeadlineH11Protocol(HeaderDeadline, H11Protocol):
    """:class:`H11Protocol` that closes connections too slow to send headers."""


def httptools_available() -> bool:
    """Whether uvicorn's httptools protocol can be used (``httptools`` is installed)."""
    return importlib.util.find_spec("httptools") is not None


def protocol_class(http: HttpImplementation = "auto") -> type[HeaderDeadline]:
    """The header-deadline protocol over ``http``: ``auto`` picks httptools when it is
    installed, h11 otherwise (as uvicorn's ``auto``)."""
    if http == "h11" or (http == "auto" and not httptools_available()):
        return HeaderDeadlineH11Protocol
    from api.protocol_httptools import HeaderDeadlineHttpToolsProtocol

    return HeaderDeadlineHttpToolsProtocol


def with_header_deadline(
    seconds: float, http: HttpImplementation = "auto", max_per_client: int | None = None
) -> type[HeaderDeadline]:
    """The protocol class for a server whose clients get ``seconds`` for a request (headers
    and body) and hold at most ``max_per_client`` connections each."""
    base = protocol_class(http)
    return type(
        base.__name__,
        (base,),
        {"timeout_request": seconds, "max_per_client": max_per_client, "_clients": {}},
    )
