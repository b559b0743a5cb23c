"""semwm.http_connection: answers framed by httptools, errors as http.client raises them.

Each case is served by a scripted socket server on 127.0.0.1 that writes exact bytes,
so framing (Content-Length, chunked, Connection: close) and broken peers are real.
"""

from __future__ import annotations

import http.client
import socket
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import pytest

from semwm.http_connection import HttpConnection

Script = Callable[[socket.socket, list[bytes]], None]


def _read_request(conn: socket.socket) -> bytes:
    data = b""
    while b"\r\n\r\n" not in data:
        chunk = conn.recv(65536)
        if not chunk:
            return data
        data += chunk
    head, _, rest = data.partition(b"\r\n\r\n")
    length = 0
    for line in head.split(b"\r\n")[1:]:
        name, _, value = line.partition(b":")
        if name.strip().lower() == b"content-length":
            length = int(value)
    while len(rest) < length:
        rest += conn.recv(65536)
    return head + b"\r\n\r\n" + rest


@contextmanager
def scripted_server(script: Script) -> Iterator[tuple[int, list[bytes]]]:
    """A one-connection server on a free loopback port running ``script(conn, seen)``;
    ``seen`` collects the requests it read."""
    listener = socket.socket()
    listener.bind(("127.0.0.1", 0))
    listener.listen(1)
    seen: list[bytes] = []

    def serve() -> None:
        conn, _ = listener.accept()
        with conn:
            script(conn, seen)

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    try:
        yield listener.getsockname()[1], seen
    finally:
        thread.join(timeout=5)
        listener.close()


def answer(body: bytes, extra: bytes = b"") -> bytes:
    return (
        b"HTTP/1.1 200 OK\r\ncontent-type: application/json\r\nX-Semwm-Commit: 7\r\n"
        + extra
        + b"content-length: "
        + str(len(body)).encode()
        + b"\r\n\r\n"
        + body
    )


def test_requests_share_the_connection_and_answers_are_framed_by_length() -> None:
    def script(conn: socket.socket, seen: list[bytes]) -> None:
        for body in (b'{"a":1}', b'{"b":2}'):
            seen.append(_read_request(conn))
            # the answer in two writes: the parser waits for the whole body
            data = answer(body)
            conn.sendall(data[:30])
            conn.sendall(data[30:])

    with scripted_server(script) as (port, seen):
        connection = HttpConnection("127.0.0.1", port)
        first = connection.request("POST", "/detections", b'{"x":1}', {"accept": "json"})
        second = connection.request("GET", "/health", None, {})
        connection.close()
    assert (first.status, first.body, first.keep_alive) == (200, b'{"a":1}', True)
    assert ("x-semwm-commit", "7") in first.headers  # names lower-cased
    assert second.body == b'{"b":2}'
    post, get = seen
    assert post.startswith(b"POST /detections HTTP/1.1\r\nHost: 127.0.0.1:")
    assert b"accept: json\r\n" in post and b"Content-Length: 7\r\n" in post
    assert post.endswith(b'\r\n\r\n{"x":1}')
    assert get.startswith(b"GET /health HTTP/1.1\r\n") and b"Content-Length" not in get


def test_a_chunked_answer_and_connection_close() -> None:
    def script(conn: socket.socket, seen: list[bytes]) -> None:
        seen.append(_read_request(conn))
        conn.sendall(
            b"HTTP/1.1 422 Unprocessable Entity\r\ntransfer-encoding: chunked\r\n"
            b'connection: close\r\n\r\n5\r\n{"det\r\n6\r\nail":1\r\n1\r\n}\r\n0\r\n\r\n'
        )

    with scripted_server(script) as (port, _):
        result = HttpConnection("127.0.0.1", port).request("GET", "/x", None, {})
    assert (result.status, result.body, result.keep_alive) == (422, b'{"detail":1}', False)


def test_a_peer_that_closes_before_answering_is_remote_disconnected() -> None:
    def script(conn: socket.socket, seen: list[bytes]) -> None:
        seen.append(_read_request(conn))

    with scripted_server(script) as (port, _):
        connection = HttpConnection("127.0.0.1", port)
        with pytest.raises(http.client.RemoteDisconnected):
            connection.request("GET", "/health", None, {})
    assert issubclass(http.client.RemoteDisconnected, ConnectionResetError)  # retryable


def test_a_peer_that_closes_mid_answer_and_a_malformed_answer() -> None:
    def cut(conn: socket.socket, seen: list[bytes]) -> None:
        seen.append(_read_request(conn))
        conn.sendall(answer(b'{"long":"body"}')[:-5])

    with scripted_server(cut) as (port, _), pytest.raises(http.client.IncompleteRead):
        HttpConnection("127.0.0.1", port).request("GET", "/", None, {})

    def garbage(conn: socket.socket, seen: list[bytes]) -> None:
        seen.append(_read_request(conn))
        conn.sendall(b"NOT HTTP AT ALL\r\n\r\n")

    malformed = pytest.raises(http.client.HTTPException, match="malformed HTTP answer")
    with scripted_server(garbage) as (port, _), malformed:
        HttpConnection("127.0.0.1", port).request("GET", "/", None, {})


def test_a_head_answer_ends_at_its_headers() -> None:
    def script(conn: socket.socket, seen: list[bytes]) -> None:
        seen.append(_read_request(conn))
        conn.sendall(b"HTTP/1.1 200 OK\r\ncontent-length: 500\r\n\r\n")
        conn.recv(10)  # wait for the client to close

    with scripted_server(script) as (port, _):
        connection = HttpConnection("127.0.0.1", port, timeout=5.0)
        result = connection.request("HEAD", "/", None, {})
        connection.close()
    assert (result.status, result.body, result.keep_alive) == (200, b"", False)
