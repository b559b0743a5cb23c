"""A request's time by stage (``api.stages``, ``semwm_ingest_stage_seconds`` in /metrics)."""

from __future__ import annotations

import itertools
import json
from collections.abc import Iterator
from typing import Any

import pytest
from api_helpers import make_app, scene
from fastapi.testclient import TestClient
from test_api_operations import scrape, value

from api import stages
from api.app import create_app
from api.deps import get_world
from api.ingest_fast import INLINE_BODY
from api.service import WorldService
from api.settings import Settings


def test_stages_are_exclusive_and_add_up(monkeypatch: pytest.MonkeyPatch) -> None:
    ticks = itertools.count()
    monkeypatch.setattr(stages, "clock", lambda: float(next(ticks)))
    timed, token = stages.start()  # t = 0
    try:
        with stages.stage("read"):  # 1 .. 2
            pass
        with stages.stage("service"):  # 3 .. 4, 7 .. 8, 9 .. 10
            with stages.stage("model"), stages.stage("core"):  # 4 .. 5, 6 .. 7; 5 .. 6
                pass
            with stages.stage("model"):  # 8 .. 9
                pass
    finally:
        stages.stop(token)
    seconds = timed.finish()  # 11
    assert seconds == {
        "other": 1 + 1 + 1,  # 0 .. 1, 2 .. 3, 10 .. 11
        "read": 1,
        "service": 1 + 1 + 1,
        "model": 1 + 1 + 1,
        "core": 1,
    }
    assert sum(seconds.values()) == 11


def test_a_collection_is_taken_from_the_stage_it_interrupted(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    ticks = itertools.count()
    monkeypatch.setattr(stages, "clock", lambda: float(next(ticks)))
    timed, token = stages.start()  # t = 0
    with stages.stage("model"):  # 1 .. 5
        stages._collection("start", {})  # 2
        stages._collection("stop", {})  # 3
        stages._collection("start", {})  # 4
        stages.stop(token)
        stages._collection("stop", {})  # not in a timed request any more: nothing
    assert timed.finish() == {"other": 1 + 1, "model": 5 - 1 - 1, "gc": 1}  # finish: 6


def test_a_stage_outside_a_timed_request_does_nothing() -> None:
    with stages.stage("model"):
        pass
    assert stages.stage("model") is stages.stage("read")  # the shared no-op


def test_totals_list_every_stage_first() -> None:
    totals = stages.StageTotals()
    totals.add({"read": 1.0, "model": 2.0})
    totals.add({"model": 0.5, "core": 0.25})  # a stage a benchmark times
    count, seconds = totals.totals()
    assert count == 2
    assert list(seconds)[: len(stages.STAGES)] == list(stages.STAGES)
    assert seconds["model"] == 2.5 and seconds["read"] == 1.0 and seconds["lock"] == 0.0
    assert seconds["core"] == 0.25


def _stage_samples(client: TestClient) -> tuple[dict[str, float], dict[str, float], Any]:
    samples = scrape(client)
    sums = {s: value(samples, "semwm_ingest_stage_seconds_sum", stage=s) for s in stages.STAGES}
    counts = {s: value(samples, "semwm_ingest_stage_seconds_count", stage=s) for s in stages.STAGES}
    return sums, counts, samples


def test_stage_timing_is_off_by_default(client: TestClient) -> None:
    assert client.post("/detections", json={"detections": scene(0.0)}).status_code == 200
    assert "semwm_ingest_stage_seconds" not in client.get("/metrics").text


@pytest.fixture
def timed_client(service: WorldService) -> Iterator[TestClient]:
    with TestClient(make_app(service, stage_timing=True)) as test_client:
        yield test_client


def test_metrics_time_every_accepted_request_by_stage(timed_client: TestClient) -> None:
    client = timed_client
    sums, counts, _ = _stage_samples(client)
    assert set(counts.values()) == {0.0} and set(sums.values()) == {0.0}
    for step in range(3):
        assert client.post("/detections", json={"detections": scene(step * 0.5)}).status_code == 200
    # refused (422, 409) and passed to the route (a malformed key): not counted
    bad = [{"time": 1.5, "class": "Mug", "position": [0, 0]}]
    assert client.post("/detections", json={"detections": bad}).status_code == 422
    assert client.post("/detections", json=scene(0.0)[0]).status_code == 409
    sums, counts, samples = _stage_samples(client)
    assert set(counts.values()) == {3.0}
    for name in ("read", "parse", "lock", "sources", "save", "model", "notify", "service"):
        assert sums[name] > 0.0, name
    assert sums["respond"] > 0.0 and sums["other"] > 0.0
    assert sums["handoff"] == 0.0  # small bodies on a free world: applied on the event loop
    # the stages add up to the requests' time in the app, within the whole request's
    accepted_latency = value(samples, "semwm_ingest_latency_seconds_sum")
    assert sum(sums.values()) < accepted_latency
    assert sums["model"] < value(samples, "semwm_ingest_apply_seconds_sum")


def test_a_large_body_is_timed_in_its_ingest_thread(service: WorldService) -> None:
    app = create_app(
        Settings(
            knowledge=service.knowledge_path,
            max_batch=200,
            allowed_hosts=("testserver",),
            stage_timing=True,
        )
    )
    app.dependency_overrides[get_world] = lambda: service
    batch = [
        {"time": 1.0, "class": "Cup", "position": [0.5 * (i % 10), 0.5 * (i // 10)], "source": "r1"}
        for i in range(60)
    ]
    body = json.dumps({"detections": batch}).encode()
    assert len(body) > INLINE_BODY
    with TestClient(app) as client:
        headers = {"content-type": "application/json"}
        assert client.post("/detections", content=body, headers=headers).status_code == 200
        sums, counts, _ = _stage_samples(client)
    assert set(counts.values()) == {1.0}
    assert sums["handoff"] > 0.0  # the hand-over to a thread and back
    for name in ("parse", "lock", "model", "notify"):  # timed in the ingest thread
        assert sums[name] > 0.0, name
