"""uvicorn's HTTP protocol with a deadline for a request's headers (against slowloris).

uvicorn closes idle keep-alive connections after ``timeout_keep_alive``, but a
connection that never sends anything, or sends its headers one byte at a time, is
kept forever: a few hundred of them fill ``limit_concurrency`` and every real client
gets 503. This protocol gives each connection ``timeout_request`` seconds to finish
a request's headers, counted from the connection (first request) or from the end of
the previous response (the next one); a connection that misses it is closed.
"""

from __future__ import annotations

import asyncio
from typing import Any

from uvicorn.protocols.http.h11_impl import H11Protocol


class HeaderDeadlineH11Protocol(H11Protocol):
    """:class:`H11Protocol` that closes connections too slow to send headers."""

    timeout_request = 10.0
    """Seconds a client has to send a request's headers (set per server, see
    :func:`with_header_deadline`)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._deadline: asyncio.TimerHandle | None = None

    def _arm(self) -> None:
        """Start the clock for the next request's headers."""
        self._disarm()
        waiting_since = self.cycle  # a new request replaces it once its headers are in
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


def with_header_deadline(seconds: float) -> type[HeaderDeadlineH11Protocol]:
    """The protocol class for a server whose clients get ``seconds`` for their headers."""
    return type(
        "HeaderDeadlineH11Protocol", (HeaderDeadlineH11Protocol,), {"timeout_request": seconds}
    )
