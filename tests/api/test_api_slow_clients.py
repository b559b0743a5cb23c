"""Issue 13 item 3: slow clients (slowloris) cannot hold connections forever."""

from __future__ import annotations

import asyncio
import socket
import time
from pathlib import Path

import httpx
import pytest
from fastapi import FastAPI

from api.protocol import HeaderDeadlineH11Protocol, httptools_available
from api.protocol_httptools import HeaderDeadlineHttpToolsProtocol
from api.settings import Settings
from api.testing import running_server, serving

SIM1 = Path(__file__).parents[2] / "knowledge" / "sim1.yaml"

# the header deadline is a mixin over both of uvicorn's HTTP/1.1 implementations
protocols = pytest.mark.parametrize("http", ["h11", "httptools"])


def closed_after(sock: socket.socket, limit: float) -> float | None:
    """Seconds until the server closes ``sock`` (reads to EOF), or None within ``limit``."""
    start = time.monotonic()
    sock.settimeout(limit)
    try:
        while sock.recv(4096):
            pass
    except TimeoutError:
        return None
    return time.monotonic() - start


@protocols
def test_idle_and_byte_by_byte_connections_are_closed_at_the_header_deadline(http: str) -> None:
    settings = Settings(knowledge=SIM1, port=0, timeout_request=1.0, limit_concurrency=4, http=http)
    with running_server(settings) as url:
        port = int(url.rsplit(":", 1)[1])
        idle = [socket.create_connection(("127.0.0.1", port)) for _ in range(4)]
        slow = socket.create_connection(("127.0.0.1", port))
        slow.sendall(b"GET /health HTTP/1.1\r\nHost: 127.0.0.1\r\n")  # headers never end
        for sock in [*idle, slow]:
            waited = closed_after(sock, limit=5.0)
            assert waited is not None and waited < 3.0, waited
            sock.close()
        # the slots they held are free again: a real client is served, not 503
        assert httpx.get(f"{url}/health", timeout=5).status_code == 200


@protocols
def test_a_kept_alive_client_gets_a_new_deadline_for_each_request(http: str) -> None:
    settings = Settings(
        knowledge=SIM1, port=0, timeout_request=1.0, timeout_keep_alive=30.0, http=http
    )
    with running_server(settings) as url, httpx.Client(base_url=url, timeout=5) as client:
        for _ in range(3):  # each request well within its own second
            assert client.get("/health").status_code == 200
            time.sleep(0.4)
        # an open connection that stops sending is closed at the deadline, not at 30 s
        port = int(url.rsplit(":", 1)[1])
        with socket.create_connection(("127.0.0.1", port)) as sock:
            sock.sendall(b"GET /health HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n")
            time.sleep(0.2)
            sock.sendall(b"GET /health HTTP/1.1\r\nHost: 127.0.0.1\r\n")  # second one stalls
            waited = closed_after(sock, limit=5.0)
            assert waited is not None and waited < 3.0, waited


@protocols
def test_a_pipelined_request_slower_than_the_deadline_is_served_whole(http: str) -> None:
    """The deadline is for headers: a request whose headers are in is never cut."""
    app = FastAPI()

    @app.get("/slow")
    async def slow() -> dict[str, bool]:
        await asyncio.sleep(1.5)
        return {"done": True}

    settings = Settings(knowledge=SIM1, port=0, timeout_request=1.0, http=http)
    with serving(app, settings) as url:
        port = int(url.rsplit(":", 1)[1])
        with socket.create_connection(("127.0.0.1", port)) as sock:
            sock.sendall(
                b"GET /slow HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n"
                b"GET /slow HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n"
            )
            received = b""
            sock.settimeout(6.0)
            while received.count(b'{"done":true}') < 2:
                chunk = sock.recv(4096)
                assert chunk, f"closed after {received!r}"
                received += chunk
        assert received.count(b"HTTP/1.1 200 OK") == 2


def test_auto_picks_httptools_when_installed() -> None:
    settings = Settings(knowledge=SIM1, port=0)
    protocol = settings.uvicorn_options()["http"]
    expected = (
        HeaderDeadlineHttpToolsProtocol if httptools_available() else HeaderDeadlineH11Protocol
    )
    assert issubclass(protocol, expected)
    assert protocol.timeout_request == settings.timeout_request
    h11 = Settings(knowledge=SIM1, port=0, http="h11").uvicorn_options()["http"]
    assert issubclass(h11, HeaderDeadlineH11Protocol)
