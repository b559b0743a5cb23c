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

    _deadline: asyncio.TimerHandle | None = None

    def _arm(self) -> None:
        """Start the clock for the next request's headers."""
        self._disarm()
        waiting_since = self.cycle  # a new request replaces it once its headers are in
        if waiting_since is not None and not waiting_since.response_complete:
            # a pipelined request already in (its headers complete) is being served: its
            # own response re-arms the clock when it is sent
            return
        self._deadline = self.loop.call_later(self.timeout_request, self._too_slow, waiting_since)

    def _disarm(self) -> None:
        if self._deadline is not None:
            self._deadline.cancel()
            self._deadline = None

    def _too_slow(self, waiting_since: object) -> None:
        self._deadline = None
        if self.cycle is waiting_since and not self.transport.is_closing():
            self.logger.info("closing a connection that sent no complete request headers in time")
            self.transport.close()

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        super().connection_made(transport)
        self._arm()

    def on_response_complete(self) -> None:
        super().on_response_complete()
        if not self.transport.is_closing():
            self._arm()

    def connection_lost(self, exc: Exception | None) -> None:
        self._disarm()
        super().connection_lost(exc)


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


def with_header_deadline(seconds: float, http: HttpImplementation = "auto") -> type[HeaderDeadline]:
    """The protocol class for a server whose clients get ``seconds`` for their headers."""
    base = protocol_class(http)
    return type(base.__name__, (base,), {"timeout_request": seconds})
