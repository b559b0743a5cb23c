"""The bridge without a network: payloads go through the same path as POST /detections."""

from __future__ import annotations

import json
from collections.abc import Iterator
from typing import Any

import pytest
from fastapi.testclient import TestClient
from mqtt_helpers import KNOWLEDGE, RecordingService

from api.app import create_app
from api.deps import get_world
from api.mqtt_bridge import BridgeCore
from api.service import WorldService
from api.settings import Settings
from semwm.mqtt.protocol import Topics

MAX_BATCH = 5
TOPICS = Topics("lab")


@pytest.fixture
def core(service: WorldService) -> BridgeCore:
    return BridgeCore(service, TOPICS, world_rate=10.0, max_batch=MAX_BATCH)


@pytest.fixture
def client(service: WorldService) -> Iterator[TestClient]:
    app = create_app(
        Settings(knowledge=KNOWLEDGE, max_batch=MAX_BATCH, allowed_hosts=("testserver",))
    )
    app.dependency_overrides[get_world] = lambda: service
    with TestClient(app) as test_client:
        yield test_client


def encode(body: Any) -> bytes:
    return json.dumps(body).encode()


def state(client: TestClient) -> dict[str, Any]:
    return {
        "world": client.get("/world").json(),
        "hypotheses": client.get("/hypotheses", params={"limit": 1000}).json(),
        "health": client.get("/health").json(),
    }


def scan(t: float) -> dict[str, Any]:
    """A cup and a coke can seen at ``t``; the coke can by a named camera."""
    return {"detections": [{"time": t, "class": "Cup", "position": [1.0, 2.0]},
                           {"time": t, "class": "CokeCan", "position": [3.0, 1.0],
                            "source": "cam"}]}  # fmt: skip


def test_batches_are_applied_and_the_topic_names_the_source(
    core: BridgeCore, service: RecordingService
) -> None:
    for step in range(2):  # sim1 publishes an object from its second detection on
        assert core.handle("lab/detections/r1", encode(scan(0.2 * step))) is None
    assert core.counts.applied == 2
    assert core.counts.detections == 4
    assert core.counts.sources["r1"].batches == 2
    assert core.rate.due() == 0.0  # a world publication is pending
    assert sorted(o.cls for o in service.world().objects) == ["CokeCan", "Cup"]
    assert [[d["source"] for d in batch] for batch in service.applied] == [["r1", "cam"]] * 2


def test_world_json_is_the_get_world_body(core: BridgeCore, client: TestClient) -> None:
    for step in range(2):
        core.handle("lab/detections/r1", encode(scan(0.2 * step)))
    assert len(core.world_json()["objects"]) == 2
    assert core.world_json() == client.get("/world").json()


@pytest.mark.parametrize(
    "body",
    [
        {"detections": [{"time": 0.0, "class": "Cup", "position": [1.0, 2.0]},
                        {"time": 0.1, "class": "Cup", "position": [1.0]},
                        {"time": "x", "class": "Mug", "position": [1.0, 2.0]}]},
        {"time": 0.0, "class": "Unknown", "position": [1.0, 2.0]},
        {"detections": [], "extra": 1},
        {"detections": [{"time": 0.0, "class": "Cup", "position": [1.0, 2.0]}] * (MAX_BATCH + 1)},
    ],
    ids=["batch-with-two-bad", "unknown-class", "empty-batch", "too-long"],
)  # fmt: skip
def test_invalid_payload_is_refused_with_the_http_422_body_and_changes_nothing(
    core: BridgeCore, client: TestClient, body: dict[str, Any]
) -> None:
    client.post("/detections", json={"time": 0.0, "class": "Cup", "position": [5.0, 5.0]})
    before = state(client)
    refusal = core.handle("lab/detections/r1", encode(body))
    assert refusal is not None
    assert refusal.topic == "lab/errors/r1"
    filled = json.loads(json.dumps(body))
    if "detections" in filled and isinstance(filled["detections"], list):
        filled["detections"] = [{**d, "source": "r1"} for d in filled["detections"]]
    elif "detections" not in filled:
        filled["source"] = "r1"
    http = client.post("/detections", json=filled)
    assert http.status_code == 422
    assert refusal.payload == {"status": 422, **http.json(), "topic": "lab/detections/r1"}
    assert state(client) == before
    assert core.counts.refused == 1 and core.counts.applied == 0
    assert core.counts.sources["r1"].refused == 1
    assert core.rate.due() is None  # nothing to publish


def test_payload_that_is_not_json_is_refused_saying_where(core: BridgeCore) -> None:
    refusal = core.handle("lab/detections/r2", b'{"time": 0.0,')
    assert refusal is not None
    assert refusal.topic == "lab/errors/r2"
    assert refusal.payload["status"] == 422
    (item,) = refusal.payload["detail"]
    assert item["loc"] == ["body"]
    assert item["type"] == "json_invalid"
    assert "line 1 column 14" in item["msg"]


def test_too_old_batch_is_a_409_refusal(core: BridgeCore, client: TestClient) -> None:
    core.handle("lab/detections/r1", encode({"time": 100.0, "class": "Cup", "position": [1, 2]}))
    old = {"time": 1.0, "class": "Cup", "position": [1.0, 2.0]}
    refusal = core.handle("lab/detections/r1", encode(old))
    assert refusal is not None
    http = client.post("/detections", json={**old, "source": "r1"})
    assert http.status_code == 409
    assert refusal.payload == {"status": 409, **http.json(), "topic": "lab/detections/r1"}
    assert core.counts.refusals[409] == 1


def test_redelivered_payload_is_applied_once(core: BridgeCore, service: WorldService) -> None:
    payload = encode({"time": 0.0, "class": "Cup", "position": [1.0, 2.0]})
    core.handle("lab/detections/r1", payload)
    before = service.hypotheses(1000)
    assert core.handle("lab/detections/r1", payload) is None
    assert core.counts.duplicates == 1 and core.counts.applied == 1
    assert service.hypotheses(1000) == before
    # the same bytes from another source are another message
    core.handle("lab/detections/r2", payload)
    assert core.counts.applied == 2


def test_other_topics_are_ignored(core: BridgeCore) -> None:
    assert core.handle("lab/world", b"{}") is None
    assert core.handle("lab/detections/a/b", b"{}") is None
    assert core.counts.received == 0


def test_serve_refuses_a_bad_broker_url_before_starting(capsys: pytest.CaptureFixture[str]) -> None:
    from semwm.cli import main

    status = main(["serve", "--knowledge", str(KNOWLEDGE), "--mqtt", "tcp://127.0.0.1:1883"])
    assert status == 2
    assert "--mqtt: broker URL must start with mqtt://" in capsys.readouterr().err
    status = main(["serve", "--knowledge", str(KNOWLEDGE), "--mqtt", "mqtt://h:1",
                   "--mqtt-prefix", "a/#"])  # fmt: skip
    assert status == 2
    assert "--mqtt-prefix: MQTT topic prefix must not contain" in capsys.readouterr().err
