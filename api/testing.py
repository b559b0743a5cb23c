"""Run the real service (uvicorn) in a background thread: for tests and benchmarks."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager

import uvicorn
from fastapi import FastAPI

from api.app import create_app
from api.server import Server
from api.settings import Settings


@contextmanager
def running_server(settings: Settings, timeout: float = 20.0) -> Iterator[str]:
    """Serve ``create_app(settings)`` on ``settings.host`` and yield its base URL.

    ``settings.port`` 0 binds a free port chosen by the system; the URL carries the
    port actually bound. The server is shut down when the block exits.
    """
    with serving(create_app(settings), settings, timeout) as url:
        yield url


@contextmanager
def serving(app: FastAPI, settings: Settings, timeout: float = 20.0) -> Iterator[str]:
    """Serve ``app`` (built from ``settings``, maybe overridden) like :func:`running_server`."""
    config = uvicorn.Config(app, **settings.uvicorn_options(), log_level="warning")
    server = Server(config, app)
    thread = threading.Thread(target=server.run, name="semwm-uvicorn", daemon=True)
    thread.start()
    deadline = time.monotonic() + timeout
    while not server.started:
        if not thread.is_alive() or time.monotonic() > deadline:
            server.should_exit = True
            raise RuntimeError("the server did not start")
        time.sleep(0.01)
    try:
        port = server.servers[0].sockets[0].getsockname()[1]
        yield f"http://{settings.host}:{port}"
    finally:
        server.should_exit = True
        thread.join(timeout)
