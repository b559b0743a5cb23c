"""Issue 30 case 5: no client can hold the service.

One client holding 300 connections (idle, slow headers, slow bodies or SSE streams)
kept ``/health`` at 503 for 78-79 of 80 probes over 40 s: uvicorn's 256-connection
limit answers every request 503 once it is reached, slow bodies and streams were
never closed. Now a client holds at most ``max_client_connections`` (128) that
count, the deadline covers a request's body, streams have a lifetime and drop a
client that does not read, and ``/health`` and ``/ready`` answer past the limit.
"""

from __future__ import annotations

import asyncio
import contextlib
import socket
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from api.routes.live import BoundedStream
from api.settings import Settings
from api.testing import running_server

SIM1 = Path(__file__).parents[2] / "knowledge" / "sim1.yaml"


def _port(url: str) -> int:
    return int(url.rsplit(":", 1)[1])


@contextlib.contextmanager
def _held(
    port: int, count: int, source: str = "127.0.0.1", send: bytes = b""
) -> Iterator[list[socket.socket]]:
    sockets = []
    try:
        for _ in range(count):
            sock = socket.socket()
            sock.bind((source, 0))
            sock.connect(("127.0.0.1", port))
            if send:
                sock.sendall(send)
            sockets.append(sock)
        yield sockets
    finally:
        for sock in sockets:
            sock.close()


def _probe(url: str, path: str, source: str = "127.0.0.1") -> int:
    transport = httpx.HTTPTransport(local_address=source)
    with httpx.Client(base_url=url, timeout=5, transport=transport) as client:
        return client.get(path).status_code


def _all_probes_answer(url: str, source: str = "127.0.0.1", rounds: int = 10) -> None:
    answers = [_probe(url, path, source) for _ in range(rounds) for path in ("/health", "/ready")]
    assert answers == [200] * len(answers)


HOLDS = {
    "idle": b"",
    "slow headers": b"GET /health HTTP/1.1\r\nHost: 127.0.0.1\r\n",
    "slow bodies": b"POST /detections HTTP/1.1\r\nHost: 127.0.0.1\r\n"
    b"Content-Type: application/json\r\nContent-Length: 1000\r\n\r\n{",
    "streams": b"GET /world/stream HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n",
}


@pytest.mark.slow
@pytest.mark.parametrize("http", ["h11", "httptools"])
@pytest.mark.parametrize("kind", list(HOLDS))
def test_one_client_holding_300_connections_does_not_shut_the_service(http: str, kind: str) -> None:
    """Idle, slow headers, slow bodies or SSE streams (never read), 300 of them, with
    the default 10 s deadline: every probe is answered meanwhile."""
    settings = Settings(knowledge=SIM1, port=0, http=http)
    with running_server(settings) as url, _held(_port(url), 300, send=HOLDS[kind]):
        time.sleep(0.3)
        _all_probes_answer(url)  # from the flooding client's own address, too
        assert _probe(url, "/world", "127.0.0.2") == 200  # another client is served
        assert _probe(url, "/world") == 503  # the flooder's connection beyond its bound


@pytest.mark.slow
def test_with_every_slot_taken_by_many_clients_the_probes_answer() -> None:
    settings = Settings(knowledge=SIM1, port=0, limit_concurrency=64, max_client_connections=30)
    with running_server(settings) as url, contextlib.ExitStack() as stack:
        for i in range(3):  # 3 clients x 30: every one of the 64 slots taken
            stack.enter_context(_held(_port(url), 30, f"127.0.0.{10 + i}"))
        time.sleep(0.3)
        assert _probe(url, "/world", "127.0.0.20") == 503  # uvicorn's limit, as before
        _all_probes_answer(url, "127.0.0.20")


@pytest.mark.slow
def test_slow_bodies_are_closed_at_the_request_deadline() -> None:
    settings = Settings(knowledge=SIM1, port=0, timeout_request=1.0)
    head = (
        b"POST /detections HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: application/json\r\n"
        b'Content-Length: 1000\r\n\r\n{"detections": ['
    )
    with running_server(settings) as url, _held(_port(url), 20, send=head) as sockets:
        started = time.monotonic()
        for sock in sockets:
            sock.settimeout(5.0)
            try:
                while sock.recv(4096):
                    pass
            except TimeoutError:
                pytest.fail("a slow body was kept past the deadline")
        assert time.monotonic() - started < 4.0
        _all_probes_answer(url, rounds=2)


@pytest.mark.slow
def test_streams_end_at_their_lifetime() -> None:
    settings = Settings(knowledge=SIM1, port=0, stream_lifetime=0.5)
    with running_server(settings) as url, httpx.Client(base_url=url, timeout=10) as client:
        started = time.monotonic()
        body = b""
        with client.stream("GET", "/world/stream") as response:
            assert response.status_code == 200
            for chunk in response.iter_bytes():  # a frame at least every 2 s (stats)
                body += chunk
                if time.monotonic() - started > 8.0:
                    pytest.fail("the stream outlived its lifetime")
        assert b"event: knowledge" in body
        assert time.monotonic() - started < 6.0  # the next frame after 0.5 s ends it


def test_a_stream_client_that_does_not_read_is_dropped() -> None:
    """Under flow control ``send`` waits while the client reads nothing: the stream
    gives each frame ``send_timeout`` s, then leaves unfinished (the server closes)."""

    async def frames() -> Any:
        for i in range(1000):
            yield f"data: {i}\n\n"

    sent: list[dict[str, Any]] = []

    async def send(message: Any) -> None:
        sent.append(message)
        if len(sent) > 3:
            await asyncio.Event().wait()  # the socket never drains

    response = BoundedStream(frames(), lifetime=60.0, send_timeout=0.2)

    async def run() -> float:
        started = time.monotonic()
        await response.stream_response(send)
        return time.monotonic() - started

    took = asyncio.run(run())
    assert 0.15 < took < 2.0
    assert len(sent) == 4 and sent[-1].get("more_body") is True  # never finished


@contextlib.contextmanager
def _stream(url: str, source: str) -> Iterator[httpx.Response]:
    """A ``GET /world/stream`` from ``source`` whose first frame came (or its refusal)."""
    transport = httpx.HTTPTransport(local_address=source)
    with (
        httpx.Client(base_url=url, timeout=10, transport=transport) as client,
        client.stream("GET", "/world/stream") as response,
    ):
        chunks = response.iter_bytes()  # kept: a dropped iterator closes the response
        if response.status_code == 200:
            next(chunks)  # the knowledge event: the stream is open
        else:
            response.read()
        yield response


def test_streams_are_bounded_in_all_and_per_client_with_retry_after() -> None:
    """``/world/stream`` is open without --read-token, as ``/world`` is (reads are open
    by design on a loopback service), so its number is bounded instead: each one holds
    a connection slot for up to an hour. One more than --max-client-streams from a
    client is 429, one more than --max-streams in all is 503, both with Retry-After;
    a stream that ends gives its slot back, and the probes and reads go on."""
    settings = Settings(knowledge=SIM1, port=0, max_streams=3, max_client_streams=2)
    with running_server(settings) as url, contextlib.ExitStack() as streams:
        for _ in range(2):
            assert streams.enter_context(_stream(url, "127.0.0.1")).status_code == 200
        with _stream(url, "127.0.0.1") as third:
            assert third.status_code == 429 and third.headers["retry-after"] == "5"
            assert "--max-client-streams 2" in third.json()["detail"]
        other = contextlib.ExitStack()
        assert other.enter_context(_stream(url, "127.0.0.2")).status_code == 200
        with _stream(url, "127.0.0.3") as beyond:
            assert beyond.status_code == 503 and beyond.headers["retry-after"] == "5"
            assert "--max-streams 3" in beyond.json()["detail"]
        _all_probes_answer(url, "127.0.0.3", rounds=2)
        assert _probe(url, "/world", "127.0.0.3") == 200
        other.close()  # 127.0.0.2's stream ends: its slot is free again
        deadline = time.monotonic() + 5.0
        while True:
            with _stream(url, "127.0.0.3") as again:
                if again.status_code == 200:
                    break
                assert again.status_code == 503
            assert time.monotonic() < deadline, "an ended stream kept its slot"
            time.sleep(0.1)
