"""One keep-alive HTTP/1.1 connection, its answers parsed by ``httptools``.

The client's transport (:class:`semwm.client.Client`). ``http.client`` parses each
answer's headers with the ``email`` package and builds a file object per answer:
about 150 µs of Python per request on a 2-core VM, as much as the service's own HTTP
layer and more than a small scan costs the world model. Here the request is written
in one ``sendall`` and the answer is fed to ``httptools``' C parser (the parser
uvicorn uses, already a dependency), which frames it by ``Content-Length`` or
chunked encoding.

Errors keep ``http.client``'s types, so a caller's retry logic reads the same:
the peer closing before any byte of the answer raises
:class:`http.client.RemoteDisconnected` (a :class:`ConnectionResetError`), closing
mid-answer :class:`http.client.IncompleteRead`, a malformed answer
:class:`http.client.HTTPException`.
"""

from __future__ import annotations

import http.client
import socket
import ssl
from collections.abc import Mapping
from typing import NamedTuple

import httptools

_CHUNK = 65536


class Answer(NamedTuple):
    """An HTTP answer: ``status``, ``headers`` (lower-case names, in order), ``body``,
    and whether the connection stays open after it (``keep_alive``)."""

    status: int
    headers: list[tuple[str, str]]
    body: bytes
    keep_alive: bool


class _Collector:
    """httptools callbacks: gathers one answer's headers and body."""

    __slots__ = ("body", "done", "headers", "headers_done", "keep_alive", "parser")

    def __init__(self) -> None:
        self.headers: list[tuple[str, str]] = []
        self.body: list[bytes] = []
        self.headers_done = False
        self.keep_alive = False
        self.done = False
        self.parser = httptools.HttpResponseParser(self)

    def on_header(self, name: bytes, value: bytes) -> None:
        self.headers.append((name.decode("latin-1").lower(), value.decode("latin-1")))

    def on_headers_complete(self) -> None:
        self.headers_done = True
        # read here: the parser forgets it once the message is complete
        self.keep_alive = bool(self.parser.should_keep_alive())

    def on_body(self, body: bytes) -> None:
        self.body.append(body)

    def on_message_complete(self) -> None:
        self.done = True


class HttpConnection:
    """A connection to ``host:port`` (TLS with ``https``), opened on the first request.

    Not thread-safe. ``timeout`` (s) bounds the connect and each wait for answer bytes.
    """

    def __init__(self, host: str, port: int | None, *, https: bool = False, timeout: float = 10.0):
        self.host = host
        self.https = https
        self.port = port if port is not None else (443 if https else 80)
        self.timeout = timeout
        default = self.port == (443 if https else 80)
        self._host_header = host if default else f"{host}:{self.port}"
        self._socket: socket.socket | None = None

    def _open(self) -> socket.socket:
        sock = socket.create_connection((self.host, self.port), timeout=self.timeout)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        if self.https:
            sock = ssl.create_default_context().wrap_socket(sock, server_hostname=self.host)
        return sock

    def request(
        self, method: str, target: str, body: bytes | None, headers: Mapping[str, str]
    ) -> Answer:
        """Send one request and read its whole answer."""
        if self._socket is None:
            self._socket = self._open()
        lines = [f"{method} {target} HTTP/1.1", f"Host: {self._host_header}"]
        lines.extend(f"{name}: {value}" for name, value in headers.items())
        if body is not None or method in ("POST", "PUT", "PATCH"):
            lines.append(f"Content-Length: {0 if body is None else len(body)}")
        head = ("\r\n".join(lines) + "\r\n\r\n").encode("latin-1")
        self._socket.sendall(head + body if body else head)
        return self._read(self._socket, head_only=method == "HEAD")

    @staticmethod
    def _read(sock: socket.socket, head_only: bool) -> Answer:
        collector = _Collector()
        parser = collector.parser
        received = 0
        while not (collector.done or (head_only and collector.headers_done)):
            chunk = sock.recv(_CHUNK)
            if not chunk:
                if received == 0:
                    raise http.client.RemoteDisconnected(
                        "Remote end closed connection without response"
                    )
                raise http.client.IncompleteRead(b"".join(collector.body))
            received += len(chunk)
            try:
                parser.feed_data(chunk)
            except httptools.HttpParserError as error:
                raise http.client.HTTPException(f"malformed HTTP answer: {error}") from error
        return Answer(
            parser.get_status_code(),
            collector.headers,
            b"".join(collector.body),
            collector.keep_alive and not head_only,
        )

    def close(self) -> None:
        if self._socket is not None:
            self._socket.close()
            self._socket = None
