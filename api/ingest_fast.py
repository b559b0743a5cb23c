"""``POST /detections`` answered without the framework's per-request work.

The ingest route is the service's hot path (a team posts 150 batches a second).
Through FastAPI each request also pays for route matching over every route,
dependency solving, a ``Request`` and a ``Response`` object and two exception
layers: about 1 ms of CPU per request on a 2-core x86_64 box, as much as the world
model spends on a scan of a few detections. This middleware sits inside every guard
(tokens, browser safety, body limit, allowed hosts, request ids, metrics: they run
first, unchanged) and answers an accepted batch itself with what the route would
answer: 200, ``IngestOut``'s JSON, the commit header and ``Idempotent-Replayed``.

A refusal (422 with every field path, 409) is answered as the app's handler of
:class:`~api.errors.ApiError` answers the route's; any other error propagates as
the route's would (the bug barrier's 500). The rest goes to the route, which stays
the one definition of the endpoint (its OpenAPI, its checks): another path or
method, a malformed ``Idempotency-Key``, a body the guard refused while it was
read. ``tests/api/test_ingest_fast.py`` holds the two paths to the same answers.
"""

from __future__ import annotations

import asyncio
import contextvars
import functools
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any, TypeVar

from starlette.responses import JSONResponse
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from api import stages as timing
from api.errors import ApiError
from api.routes.detections import apply_json
from api.schemas import MAX_KEY, ingest_out
from api.service import COMMIT_HEADER, Committed, WorldBusy, WorldService
from api.stages import StageTotals, stage
from semwm import IngestResult

PATH = "/detections"
_KEY_HEADER = b"idempotency-key"
_MALFORMED = "\0malformed"  # no header value can be this (NUL is not allowed in one)
_T = TypeVar("_T")

INLINE_BODY = 4096
"""Bodies up to this size (about 20 detections) are applied on the event loop when the
world's lock is free, no hook (the journal) writes and the body is plainly valid; else
in an ingest thread. The hand-over to a thread and back costs a small scan 250-400 µs
on a 2-core x86_64 box (the world model's data is in the other core's cache: the scan
itself runs 10-35 % slower there), as much as the scan. On the loop, the scan delays
the other requests by its own time, at most: every request that reads or changes the
world waits for its lock anyway; only /health, /metrics and static pages wait where
they would not have."""

_INGEST_THREADS = ThreadPoolExecutor(max_workers=16, thread_name_prefix="semwm-ingest")
"""Where accepted batches are applied, off the event loop. One hand-over to a thread and
back costs about 50-90 µs this way against 105-140 µs with ``anyio.to_thread.run_sync``
(its capacity limiter and task machinery; uvloop, a 2-core x86_64 box, 15 x 500 calls
of a no-op each, interleaved). Posts one at a time reuse one idle thread; concurrent
ones (up to 16, a team's robots) each wait at the world's time-ordered lock as before."""


class FastIngest:
    """Answer accepted ``POST /detections`` batches directly (see the module docstring).

    ``service``: the world service the routes use (a test's override included);
    ``max_batch``: the settings' largest batch; ``stages``: where each accepted
    request's seconds by stage are added (:mod:`api.stages`; ``None``: not timed).
    """

    def __init__(
        self,
        app: ASGIApp,
        service: Callable[[], WorldService],
        max_batch: int,
        stages: StageTotals | None = None,
    ) -> None:
        self.app = app
        self.service = service
        self.max_batch = max_batch
        self.stages = stages

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or scope["method"] != "POST" or scope["path"] != PATH:
            await self.app(scope, receive, send)
            return
        if self.stages is None:
            await self._answer(scope, receive, send)
            return
        stages, token = timing.start()
        try:
            answered = await self._answer(scope, receive, send)
        finally:
            timing.stop(token)
        if answered:
            self.stages.add(stages.finish())

    async def _answer(self, scope: Scope, receive: Receive, send: Send) -> bool:
        """Answer the request; whether it was answered here with a 200 (its stages are
        then counted), not refused or passed to the route."""
        key = _idempotency_key(scope)
        if key is _MALFORMED:  # the route says why
            await self.app(scope, receive, send)
            return False
        try:
            with stage("read"):
                raw = await _body(receive)
        except Exception as error:  # the guard's 413, a disconnect: as the route meets it
            await self.app(scope, _raising(error), send)
            return False
        try:
            committed = await self._apply(self.service(), raw, key)
        except ApiError as refusal:  # nothing was applied: the route's error answer
            answer = JSONResponse(
                status_code=refusal.status, content=refusal.body(), headers=refusal.headers
            )
            await answer(scope, receive, send)
            return False
        with stage("respond"):
            result = committed.value
            body = ingest_out(result).model_dump_json().encode()
            headers = [
                (b"content-length", str(len(body)).encode()),
                (b"content-type", b"application/json"),
                (COMMIT_HEADER.lower().encode(), str(committed.commit).encode()),
            ]
            if committed.replayed:
                headers.append((b"idempotent-replayed", b"true"))
            if committed.dropped:
                headers.append((b"x-semwm-dropped", b"late"))
            await send({"type": "http.response.start", "status": 200, "headers": headers})
            await send({"type": "http.response.body", "body": body})
        return True

    async def _apply(
        self, service: WorldService, raw: bytes, key: str | None
    ) -> Committed[IngestResult]:
        """Apply a body: on the event loop when it is small and the world is free (see
        :data:`INLINE_BODY`), else in an ingest thread."""
        if len(raw) <= INLINE_BODY and not service.hooks:
            try:
                return apply_json(service, raw, self.max_batch, key, wait=False)
            except WorldBusy:
                pass  # someone holds the world (or the body needs its full check): wait there
        with stage("handoff"):  # the stages inside count for themselves
            return await _in_worker(apply_json, service, raw, self.max_batch, key)


async def _in_worker(function: Callable[..., _T], *args: Any) -> _T:
    """``function(*args)`` in an ingest thread, with this request's context (its request
    id in the log lines the service writes)."""
    context = contextvars.copy_context()
    call = functools.partial(context.run, function, *args)
    return await asyncio.get_running_loop().run_in_executor(_INGEST_THREADS, call)


def _idempotency_key(scope: Scope) -> str | None:
    """The ``Idempotency-Key`` header, ``None`` without one, :data:`_MALFORMED` if the
    route's checks (1 to ``MAX_KEY`` characters, one header) would refuse it."""
    found = [v for k, v in scope["headers"] if k.lower() == _KEY_HEADER]
    if not found:
        return None
    key = found[0].decode("latin-1")
    return key if len(found) == 1 and 1 <= len(key) <= MAX_KEY else _MALFORMED


async def _body(receive: Receive) -> bytes:
    chunks: list[bytes] = []
    while True:
        message = await receive()
        if message["type"] != "http.request":
            raise _Disconnected(message)
        chunks.append(message.get("body", b""))
        if not message.get("more_body", False):
            return b"".join(chunks)


class _Disconnected(Exception):
    """The client left before its body was read: the route gets the same message."""

    def __init__(self, message: Message) -> None:
        super().__init__("client disconnected")
        self.message = message


def _raising(error: Exception) -> Receive:
    """A ``receive`` for the route that meets what reading the body met."""

    async def receive() -> Message:
        if isinstance(error, _Disconnected):
            return error.message
        raise error

    return receive
