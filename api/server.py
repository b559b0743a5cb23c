"""uvicorn's server, taught to end the live streams first when it shuts down.

uvicorn waits for every open response before it shuts down; a page left open on
``GET /world/stream`` would hold a Ctrl-C (or a test's shutdown) forever. This
server ends those streams, then shuts down as uvicorn does.
"""

from __future__ import annotations

import socket

import uvicorn
from fastapi import FastAPI

from api.app import end_streams


class Server(uvicorn.Server):
    """A :class:`uvicorn.Server` for ``app`` that ends its push streams on shutdown."""

    def __init__(self, config: uvicorn.Config, app: FastAPI) -> None:
        super().__init__(config)
        self.app = app

    async def shutdown(self, sockets: list[socket.socket] | None = None) -> None:
        end_streams(self.app)
        await super().shutdown(sockets)
