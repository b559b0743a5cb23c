"""``GET /world/stream`` over a real server: the SSE format a program reads, and the feed."""

from __future__ import annotations

import asyncio
import json
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
from api_helpers import scene

from api.feed import WorldFeed, sse_frame
from api.service import WorldService
from api.settings import Settings
from api.testing import running_server

TIMEOUT = 20.0  # s: bound on every wait; the stream normally answers in ~0.1 s


def events(response: httpx.Response) -> Iterator[tuple[str, dict[str, Any], str | None]]:
    """Parse Server-Sent Events: (event, JSON data, id) per frame; comments skipped."""
    name, data, event_id = "message", [], None
    for line in response.iter_lines():
        if line == "":
            if data:
                yield name, json.loads("\n".join(data)), event_id
            name, data, event_id = "message", [], None
        elif line.startswith(":"):
            continue
        else:
            field, _, text = line.partition(":")
            text = text.removeprefix(" ")
            if field == "event":
                name = text
            elif field == "data":
                data.append(text)
            elif field == "id":
                event_id = text


def next_event(stream: Iterator[tuple[str, dict[str, Any], str | None]], kind: str,
               until: Any = lambda data: True) -> dict[str, Any]:  # fmt: skip
    for name, data, _ in stream:
        if name == kind and until(data):
            return data
    raise AssertionError(f"the stream ended before a {kind!r} event")


def test_a_program_follows_the_world_over_sse(knowledge_file: Path) -> None:
    with (
        running_server(Settings(knowledge=knowledge_file, port=0)) as url,
        httpx.Client(base_url=url, timeout=TIMEOUT) as client,
        client.stream("GET", "/world/stream") as response,
    ):
        assert response.status_code == 200
        assert response.headers["content-type"].startswith("text/event-stream")
        stream = events(response)
        knowledge = next_event(stream, "knowledge")
        assert knowledge["version"] == 1 and knowledge["dimension"] == 2
        assert "Robot" in knowledge["classes"]
        first = next_event(stream, "world")
        assert first["objects"] == [] and first["time"] is None

        posted = client.post("/detections", json={"detections": scene(0.0)})
        assert posted.status_code == 200
        world = next_event(stream, "world", lambda d: d["time"] == 0.0)
        assert world == {**world, "objects": client.get("/world").json()["objects"]}
        assert {o["class"] for o in world["objects"]} == {"Cup", "CokeCan", "Robot"}
        assert [d["class"] for d in world["detections"]] == ["Cup", "CokeCan", "Robot"]
        assert world["changes"] == ["detections"]
        assert world["hypotheses"] == client.get("/health").json()["hypotheses"]
        assert world["rate"] > 0 and world["seq"] > first["seq"]

        assert client.post("/reset").status_code == 200
        reset = next_event(stream, "world", lambda d: "reset" in d["changes"])
        assert reset["objects"] == []

        assert client.post("/knowledge/reload").status_code == 200
        assert next_event(stream, "knowledge")["version"] == 2


def test_an_open_stream_does_not_hold_the_shutdown(knowledge_file: Path) -> None:
    received: list[str] = []
    opened = threading.Event()

    def follow(url: str) -> None:
        with (
            httpx.Client(timeout=TIMEOUT) as client,
            client.stream("GET", f"{url}/world/stream") as r,
        ):
            opened.set()
            received.extend(name for name, _, _ in events(r))

    with running_server(Settings(knowledge=knowledge_file, port=0)) as url:
        reader = threading.Thread(target=follow, args=(url,), daemon=True)
        reader.start()
        assert opened.wait(TIMEOUT)
    reader.join(TIMEOUT)
    assert not reader.is_alive()  # the stream ended when the server stopped
    assert received[:2] == ["knowledge", "world"]


def test_sse_frame_format() -> None:
    assert sse_frame("world", {"a": 1}, 7) == 'id: 7\nevent: world\ndata: {"a":1}\n\n'
    assert sse_frame("stats", {}) == "event: stats\ndata: {}\n\n"


def test_the_feed_throttles_bursts_and_keeps_every_detection(service: WorldService) -> None:
    """50 batches in a burst give a few ``world`` events, with all 150 detections."""

    interval = 0.2
    burst: list[float] = []

    async def run() -> list[dict[str, Any]]:
        feed = WorldFeed(service, interval=interval, keepalive=60.0, queue_size=100)
        await feed.start()
        worlds: list[dict[str, Any]] = []
        try:
            async with feed.subscribe() as queue:
                await queue.get()  # knowledge
                await queue.get()  # initial world
                burst.append(time.monotonic())
                for k in range(50):
                    await asyncio.to_thread(service.ingest, scene(k * 0.01), True)
                while not worlds or worlds[-1]["time"] != pytest.approx(0.49):
                    frame = await asyncio.wait_for(queue.get(), TIMEOUT)
                    assert frame is not None
                    worlds.append(json.loads(frame.split("data: ", 1)[1]))
                burst.append(time.monotonic())
        finally:
            await feed.stop()
        return worlds

    worlds = asyncio.run(run())
    # at most one world per interval (plus the first), however slow this machine is today
    assert 1 <= len(worlds) <= 2 + (burst[1] - burst[0]) / interval
    assert len(worlds) < 50
    assert sum(len(w["detections"]) for w in worlds) == 150
    assert [w["seq"] for w in worlds] == sorted({w["seq"] for w in worlds})


def test_a_lagging_subscriber_keeps_the_latest_frames(service: WorldService) -> None:
    async def run() -> list[str | None]:
        feed = WorldFeed(service, interval=0.0, keepalive=60.0, queue_size=2)
        await feed.start()
        try:
            async with feed.subscribe() as queue:
                for k in range(5):
                    await asyncio.to_thread(service.ingest, scene(k * 0.1), True)
                    await asyncio.sleep(0.05)
                while feed._last_world is None or feed._last_world["time"] != pytest.approx(0.4):
                    await asyncio.sleep(0.01)
                return [queue.get_nowait() for _ in range(queue.qsize())]
        finally:
            await feed.stop()

    frames = asyncio.run(run())
    assert len(frames) == 2
    assert frames[-1] is not None and '"time":0.4' in frames[-1]


def test_changes_nobody_watches_wake_nothing_and_a_late_subscriber_sees_them(
    service: WorldService,
) -> None:
    async def run() -> tuple[int, dict[str, Any], float]:
        feed = WorldFeed(service, interval=0.0, keepalive=60.0, queue_size=8)
        await feed.start()
        try:
            async with feed.subscribe() as queue:  # a first viewer, then gone
                await queue.get()  # knowledge
                await queue.get()  # initial world
            wakes = 0
            real_set = feed._wake.set  # type: ignore[union-attr]

            def counted() -> None:
                nonlocal wakes
                wakes += 1
                real_set()

            feed._wake.set = counted  # type: ignore[method-assign,union-attr]
            for k in range(5):
                await asyncio.to_thread(service.ingest, scene(k * 0.1), True)
            await asyncio.sleep(0.05)
            async with feed.subscribe() as queue:
                await queue.get()  # knowledge
                frame = await asyncio.wait_for(queue.get(), TIMEOUT)
                assert frame is not None
                return wakes, json.loads(frame.split("data: ", 1)[1]), feed.rate()
        finally:
            await feed.stop()

    wakes, world, rate = asyncio.run(run())
    assert wakes == 0  # five batches and nobody watching: the event loop slept on
    assert world["time"] == pytest.approx(0.4)  # the newcomer starts from the world now
    assert rate > 0.0  # the ingest rate still counts them
