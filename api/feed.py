"""The world pushed to whoever watches: Server-Sent Events frames and snapshot consumers.

:class:`WorldFeed` listens to a :class:`~api.service.WorldService`. Each applied
change marks the world dirty and wakes the feed's task, which builds at most one
snapshot per ``interval`` (so a burst of 100 batches costs a handful of world
queries, and nothing at all while nobody watches) and hands it to every
subscriber of ``GET /world/stream`` and to every consumer (the Foxglove bridge).

The event format is documented in ``docs/api.md`` ("Live stream"):

* ``knowledge``: ``{"version", "source", "dimension", "region", "classes"}``; first,
  and again after every knowledge change.
* ``world``: ``{"seq", "time", "objects", "hypotheses", "hypotheses_log10_joint",
  "clusters", "knowledge_version", "rate", "detections", "changes"}``; the whole
  world (as ``GET /world``) after each change, at most ``1 / interval`` per second.
* ``stats``: ``{"rate", "hypotheses", "objects", "time"}`` every ``keepalive``
  seconds while nothing changes (so the ingest rate decays to zero).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import threading
import time
from collections import deque
from collections.abc import AsyncIterator, Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import anyio

from api.service import WorldChange, WorldService

logger = logging.getLogger("api")

SnapshotConsumer = Callable[[Mapping[str, Any]], None]
"""Called in the event loop with each ``world`` payload; keep it short."""


def sse_frame(event: str, data: Mapping[str, Any], event_id: int | None = None) -> str:
    """One Server-Sent Events frame: ``id``, ``event`` and one ``data`` line of JSON."""
    head = f"id: {event_id}\n" if event_id is not None else ""
    body = json.dumps(data, separators=(",", ":"), allow_nan=False)
    return f"{head}event: {event}\ndata: {body}\n\n"


def detection_view(detection: Mapping[str, Any]) -> dict[str, Any]:
    """What the page draws of an applied detection."""
    return {
        "time": detection.get("time"),
        "class": detection.get("class"),
        "position": list(detection.get("position", ())),
        "source": detection.get("source"),
        "label": detection.get("label"),
    }


@dataclass
class _Pending:
    """Changes applied since the last snapshot (written under the feed's lock)."""

    dirty: bool = False
    changes: set[str] = field(default_factory=set)
    detections: deque[Mapping[str, Any]] = field(default_factory=lambda: deque(maxlen=500))
    knowledge: bool = False


class StreamSlots:
    """The ``GET /world/stream`` responses open, in all and per client (peer address).

    Each stream holds a connection slot for up to its lifetime, so without a bound one
    client (or a few) could hold every slot with streams (issue 30). :meth:`take` a
    slot before a stream starts, :meth:`give` it back when it ends; used in the event
    loop only (no lock).
    """

    RETRY_AFTER = 5  # s: about when a dropped or ended stream frees a slot

    def __init__(self, total: int, per_client: int) -> None:
        self.total = total
        self.per_client = per_client
        self._open: dict[str, int] = {}

    @property
    def open(self) -> int:
        return sum(self._open.values())

    def take(self, client: str) -> None:
        """Count a new stream of ``client``, or raise :class:`~api.errors.TooManyStreams`
        (429: the client holds ``per_client``; 503: the service holds ``total``)."""
        from api.errors import TooManyStreams

        held = self._open.get(client, 0)
        if held >= self.per_client:
            raise TooManyStreams(
                f"this client holds {held} open /world/stream responses, the most one client "
                f"may (--max-client-streams {self.per_client}); close one, or retry after "
                f"{self.RETRY_AFTER} s",
                per_client=True,
                retry_after=self.RETRY_AFTER,
            )
        if self.open >= self.total:
            raise TooManyStreams(
                f"the service serves {self.open} open /world/stream responses, the most it "
                f"serves (--max-streams {self.total}); retry after {self.RETRY_AFTER} s",
                per_client=False,
                retry_after=self.RETRY_AFTER,
            )
        self._open[client] = held + 1

    def give(self, client: str) -> None:
        """A stream of ``client`` ended (its slot is free)."""
        left = self._open.get(client, 0) - 1
        if left > 0:
            self._open[client] = left
        else:
            self._open.pop(client, None)


class WorldFeed:
    """Throttled world snapshots for push subscribers.

    Parameters
    ----------
    service
        The world service to listen to.
    interval
        Shortest time between two ``world`` events (s).
    keepalive
        A ``stats`` event is sent after this long without a change (s).
    rate_window
        The ingest rate is the detections applied in the last ``rate_window`` s,
        divided by it (detections/s).
    queue_size
        Frames a slow subscriber may lag behind; older ones are dropped (each
        ``world`` event carries the whole world, so only faded detections are lost).
    """

    def __init__(
        self,
        service: WorldService,
        interval: float = 0.1,
        keepalive: float = 2.0,
        rate_window: float = 5.0,
        queue_size: int = 16,
    ) -> None:
        self.service = service
        self.interval = interval
        self.keepalive = keepalive
        self.rate_window = rate_window
        self.queue_size = queue_size
        self._lock = threading.Lock()
        self._build_lock = threading.Lock()
        self._pending = _Pending()
        self._applied: deque[tuple[float, int]] = deque()
        self._subscribers: set[asyncio.Queue[str | None]] = set()
        self._consumers: list[SnapshotConsumer] = []
        self._seq = 0
        self._loop: asyncio.AbstractEventLoop | None = None
        self._wake: asyncio.Event | None = None
        self._task: asyncio.Task[None] | None = None
        self._running = False
        self._remove_listener: Callable[[], None] | None = None
        self._last_world: dict[str, Any] | None = None

    # -- life ---------------------------------------------------------------------------------

    async def start(self) -> None:
        """Listen to the service and run the snapshot task in the running loop."""
        self._loop = asyncio.get_running_loop()
        self._wake = asyncio.Event()
        self._running = True
        self._remove_listener = self.service.add_listener(self.on_change)
        self._task = asyncio.create_task(self._run(), name="semwm-world-feed")

    async def stop(self) -> None:
        """Stop listening, end every subscriber's stream and the task."""
        if self._remove_listener is not None:
            self._remove_listener()
            self._remove_listener = None
        self.close_streams()
        self._running = False
        if self._task is not None and self._wake is not None:
            # The flag ends the loop even where Python 3.11's wait_for swallows a
            # cancellation that races with the wake-up.
            self._wake.set()
            self._task.cancel()
            await asyncio.wait({self._task}, timeout=self.keepalive + 5.0)
            self._task = None

    def close_streams(self) -> None:
        """End every open stream (the server is shutting down). Call in the loop."""
        for queue in list(self._subscribers):
            _offer(queue, None)

    @property
    def subscriber_count(self) -> int:
        return len(self._subscribers)

    def add_consumer(self, consumer: SnapshotConsumer) -> None:
        """Also hand each ``world`` payload to ``consumer`` (in the event loop)."""
        self._consumers.append(consumer)
        self._poke()

    # -- from the service (any thread, under the service's lock) ------------------------------

    def on_change(self, change: WorldChange) -> None:
        now = time.monotonic()
        watched = bool(self._subscribers or self._consumers)
        with self._lock:
            if change.kind == "detections":
                self._applied.append((now, change.applied))
                self._trim(now)
            if not watched:
                # nobody to tell: no snapshot to build, and no wake-up of the event loop
                # (its thread would take the interpreter lock from the one applying
                # scans); the next subscriber starts from a fresh world
                self._pending = _Pending()
                self._last_world = None
                return
            pending = self._pending
            pending.dirty = True
            pending.changes.add(change.kind)
            if change.kind == "detections":
                # the views are built when a snapshot is published
                pending.detections.extend(change.detections)
            elif change.kind == "knowledge":
                pending.knowledge = True
        self._poke()

    def _poke(self) -> None:
        wake = self._wake
        if self._loop is not None and wake is not None and not wake.is_set():
            with contextlib.suppress(RuntimeError):  # the loop is closed: nobody to tell
                self._loop.call_soon_threadsafe(wake.set)

    # -- subscribers --------------------------------------------------------------------------

    @contextlib.asynccontextmanager
    async def subscribe(self) -> AsyncIterator[asyncio.Queue[str | None]]:
        """A queue of SSE frames, starting with the knowledge and the current world.

        ``None`` in the queue means the stream ends.
        """
        queue: asyncio.Queue[str | None] = asyncio.Queue(self.queue_size)
        knowledge = await anyio.to_thread.run_sync(self.knowledge_payload)
        world = self._last_world
        if world is None:
            world = await anyio.to_thread.run_sync(self._world_payload, [], ["initial"])
        _offer(queue, sse_frame("knowledge", knowledge))
        _offer(queue, sse_frame("world", world, world["seq"]))
        self._subscribers.add(queue)
        try:
            yield queue
        finally:
            self._subscribers.discard(queue)

    # -- payloads -----------------------------------------------------------------------------

    def knowledge_payload(self) -> dict[str, Any]:
        knowledge = self.service.knowledge
        region = knowledge.world.region
        return {
            "version": self.service.knowledge_version,
            "source": knowledge.source,
            "dimension": knowledge.dimension,
            "region": [list(axis) for axis in region] if region is not None else None,
            "classes": sorted(knowledge.classes),
        }

    def rate(self, now: float | None = None) -> float:
        """Detections applied per second over the last ``rate_window`` seconds."""
        now = time.monotonic() if now is None else now
        with self._lock:
            self._trim(now)
            total = sum(n for _, n in self._applied)
        return total / self.rate_window

    def _trim(self, now: float) -> None:
        while self._applied and self._applied[0][0] < now - self.rate_window:
            self._applied.popleft()

    def _world_payload(
        self, detections: list[dict[str, Any]], changes: list[str]
    ) -> dict[str, Any]:
        with self._build_lock:
            state = self.service.world()
            stats = self.service.stats()
            self._seq += 1
            seq = self._seq
        payload: dict[str, Any] = state.to_dict()
        payload.update(
            seq=seq,
            hypotheses=stats["hypotheses"],
            hypotheses_log10_joint=stats["hypotheses_log10_joint"],
            clusters=stats["clusters"],
            knowledge_version=stats["knowledge_version"],
            rate=self.rate(),
            detections=detections,
            changes=changes,
        )
        self._last_world = payload
        return payload

    def _stats_payload(self) -> dict[str, Any]:
        stats = self.service.stats()
        return {
            "rate": self.rate(),
            "hypotheses": stats["hypotheses"],
            "objects": stats["objects"],
            "time": stats["time"],
        }

    # -- the task -----------------------------------------------------------------------------

    async def _run(self) -> None:
        assert self._wake is not None
        while self._running:
            try:
                await asyncio.wait_for(self._wake.wait(), self.keepalive)
            except TimeoutError:
                if self._subscribers:
                    stats = await anyio.to_thread.run_sync(self._stats_payload)
                    self._broadcast(sse_frame("stats", stats))
                continue
            self._wake.clear()
            try:
                await self._publish()
            except Exception:
                logger.exception("the world feed could not publish a snapshot")
            await asyncio.sleep(self.interval)

    async def _publish(self) -> None:
        with self._lock:
            pending, self._pending = self._pending, _Pending()
        if not pending.dirty and not (self._consumers and self._last_world is None):
            return
        if not self._subscribers and not self._consumers:
            self._last_world = None  # rebuilt for the next subscriber
            return
        if pending.knowledge:
            knowledge = await anyio.to_thread.run_sync(self.knowledge_payload)
            self._broadcast(sse_frame("knowledge", knowledge))
        world = await anyio.to_thread.run_sync(
            self._world_payload,
            [detection_view(d) for d in pending.detections],
            sorted(pending.changes),
        )
        self._broadcast(sse_frame("world", world, world["seq"]))
        for consumer in self._consumers:
            try:
                consumer(world)
            except Exception:
                logger.exception("a world snapshot consumer failed")

    def _broadcast(self, frame: str) -> None:
        for queue in list(self._subscribers):
            _offer(queue, frame)


def _offer(queue: asyncio.Queue[str | None], item: str | None) -> None:
    """Put ``item``, dropping the oldest frame when the subscriber lags."""
    while True:
        try:
            queue.put_nowait(item)
            return
        except asyncio.QueueFull:
            with contextlib.suppress(asyncio.QueueEmpty):
                queue.get_nowait()
