"""``/``: the live world page, and ``GET /world/stream``: the world pushed as Server-Sent Events."""

from __future__ import annotations

import asyncio
import logging
from collections.abc import AsyncIterator, Callable
from pathlib import Path
from typing import Annotated, Any

from fastapi import APIRouter, Depends, Request
from fastapi.responses import FileResponse, StreamingResponse
from starlette.types import Receive, Scope, Send

from api.deps import SettingsDep
from api.feed import StreamSlots, WorldFeed
from api.schemas import MessageOut

logger = logging.getLogger("api")

router = APIRouter(tags=["live"])

STATIC_DIR = Path(__file__).resolve().parent.parent / "static"
"""The page's HTML, JavaScript and CSS, shipped in the package (no build step, no CDN).
Found from this file, not ``importlib.resources.files("api")``: with the tests'
directories on ``sys.path`` that could resolve ``api`` to a namespace of ``tests/api``."""


def get_feed(request: Request) -> WorldFeed:
    feed: WorldFeed = request.app.state.feed
    return feed


FeedDep = Annotated[WorldFeed, Depends(get_feed)]


@router.get("/", include_in_schema=False)
def live_page() -> FileResponse:
    """The live world page (its assets are under ``/static/``)."""
    return FileResponse(STATIC_DIR / "index.html", media_type="text/html")


@router.get(
    "/world/stream",
    summary="The world, pushed as Server-Sent Events",
    response_class=StreamingResponse,
    responses={
        200: {"content": {"text/event-stream": {}}, "description": "An endless stream"},
        429: {"model": MessageOut, "description": "This client holds --max-client-streams"},
        503: {"model": MessageOut, "description": "The service serves --max-streams"},
    },
)
async def world_stream(request: Request, feed: FeedDep, settings: SettingsDep) -> StreamingResponse:
    """Server-Sent Events: ``knowledge`` first, then ``world`` after every change.

    ``world`` carries the whole world as ``GET /world`` does, plus ``hypotheses``,
    ``rate`` (detections/s) and the ``detections`` applied since the previous
    event; at most 10 per second. ``stats`` comes every 2 s while nothing changes.
    Read it with ``curl -N``, a browser's ``EventSource`` or any SSE client; the
    format is in docs/api.md. A stream ends after ``--stream-lifetime`` (reconnect),
    and a client that stops reading is dropped after ``--stream-send-timeout``. At
    most ``--max-streams`` are open at once (one more: 503) and
    ``--max-client-streams`` per client address (429), both with ``Retry-After``.
    """
    slots: StreamSlots = request.app.state.stream_slots
    client = request.client.host if request.client is not None else ""
    slots.take(client)

    async def frames() -> AsyncIterator[str]:
        async with feed.subscribe() as queue:
            while (frame := await queue.get()) is not None:
                yield frame

    return BoundedStream(
        frames(),
        lifetime=settings.stream_lifetime,
        send_timeout=settings.stream_send_timeout,
        ended=lambda: slots.give(client),
        media_type="text/event-stream",
        headers={"Cache-Control": "no-cache", "X-Accel-Buffering": "no"},
    )


class BoundedStream(StreamingResponse):
    """A streaming response with a lifetime, that drops a client which does not read.

    Under flow control a client that stops reading makes each ``send`` wait for the
    socket to drain, for ever: the stream (and its connection slot) was never freed
    (issue 30). Each frame now has ``send_timeout`` s to go out; the stream ends
    cleanly after ``lifetime`` s.
    """

    def __init__(
        self,
        content: AsyncIterator[str],
        *,
        lifetime: float,
        send_timeout: float,
        ended: Callable[[], None] | None = None,
        **options: Any,
    ) -> None:
        super().__init__(content, **options)
        self.lifetime = lifetime
        self.send_timeout = send_timeout
        self.ended = ended

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        """The response; ``ended`` is called however it ends (its slot is given back)."""
        try:
            await super().__call__(scope, receive, send)
        finally:
            if self.ended is not None:
                self.ended()

    async def stream_response(self, send: Send) -> None:
        await send(
            {"type": "http.response.start", "status": self.status_code, "headers": self.raw_headers}
        )
        loop = asyncio.get_running_loop()
        ends = loop.time() + self.lifetime
        async for chunk in self.body_iterator:
            body = chunk if isinstance(chunk, bytes | memoryview) else chunk.encode(self.charset)
            message = {"type": "http.response.body", "body": body, "more_body": True}
            try:
                await asyncio.wait_for(send(message), self.send_timeout)
            except TimeoutError:
                # returning unfinished makes the server close the connection
                logger.info("dropping a stream client that read nothing in %g s", self.send_timeout)
                return
            if loop.time() >= ends:
                break
        await send({"type": "http.response.body", "body": b"", "more_body": False})
