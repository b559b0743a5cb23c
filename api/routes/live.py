"""``/``: the live world page, and ``GET /world/stream``: the world pushed as Server-Sent Events."""

from __future__ import annotations

from collections.abc import AsyncIterator
from pathlib import Path
from typing import Annotated

from fastapi import APIRouter, Depends, Request
from fastapi.responses import FileResponse, StreamingResponse

from api.feed import WorldFeed

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
    responses={200: {"content": {"text/event-stream": {}}, "description": "An endless stream"}},
)
async def world_stream(feed: FeedDep) -> StreamingResponse:
    """Server-Sent Events: ``knowledge`` first, then ``world`` after every change.

    ``world`` carries the whole world as ``GET /world`` does, plus ``hypotheses``,
    ``rate`` (detections/s) and the ``detections`` applied since the previous
    event; at most 10 per second. ``stats`` comes every 2 s while nothing changes.
    Read it with ``curl -N``, a browser's ``EventSource`` or any SSE client; the
    format is in docs/api.md.
    """

    async def frames() -> AsyncIterator[str]:
        async with feed.subscribe() as queue:
            while (frame := await queue.get()) is not None:
                yield frame

    return StreamingResponse(
        frames(),
        media_type="text/event-stream",
        headers={"Cache-Control": "no-cache", "X-Accel-Buffering": "no"},
    )
