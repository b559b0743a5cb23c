"""The bridge against a real Mosquitto (a private one on a free loopback port)."""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

import httpx
from mqtt_helpers import KNOWLEDGE, Inbox, RecordingService, Robot, wait_until

from api.mqtt_bridge import MqttBridge
from api.mqtt_testing import PrivateBroker
from api.settings import Settings
from api.testing import running_server
from semwm.mqtt.protocol import Topics


def scan(t: float) -> dict[str, Any]:
    return {"detections": [{"time": t, "class": "Cup", "position": [1.0, 2.0]},
                           {"time": t, "class": "CokeCan", "position": [3.0, 1.0]}]}  # fmt: skip


def test_batches_published_on_mqtt_appear_in_the_retained_world(broker: PrivateBroker) -> None:
    """The whole `semwm serve --mqtt` path: settings, lifespan, bridge, GET /world."""
    topics = Topics("t1")
    settings = Settings(
        knowledge=KNOWLEDGE, port=0, mqtt=broker.url, mqtt_prefix="t1", mqtt_world_rate=50.0
    )
    with (
        running_server(settings) as url,
        Inbox(broker.broker, [topics.world, topics.status], "inbox-t1") as inbox,
    ):
        robot = Robot(broker.broker, "robot-t1")
        robot.link.start()
        for step in range(3):
            robot.publish(topics.detections("r1"), scan(0.2 * step))
        wait_until(
            lambda: any(
                w["time"] == 0.4 and len(w["objects"]) == 2 for w in inbox.on(topics.world)
            ),
            "a world with both objects at t = 0.4 s",
        )
        over_http = httpx.get(f"{url}/world").json()
        assert inbox.on(topics.world)[-1] == over_http
        assert sorted(o["class"] for o in over_http["objects"]) == ["CokeCan", "Cup"]
        # A subscriber that comes later gets the retained world at once.
        with Inbox(broker.broker, [topics.world], "late-t1") as late:
            wait_until(lambda: bool(late.on(topics.world)), "the retained world")
            assert late.on(topics.world)[0] == over_http
        wait_until(
            lambda: any(s.get("applied") == 3 for s in inbox.on(topics.status)),
            "the status counting 3 applied batches",
        )
        robot.link.stop()
    # the service stopped: its status says so (retained)
    with Inbox(broker.broker, [topics.status], "after-t1") as after:
        wait_until(lambda: bool(after.on(topics.status)), "the retained status")
        assert after.on(topics.status)[-1]["online"] is False


def test_invalid_payload_is_reported_on_the_errors_topic_and_changes_nothing(
    broker: PrivateBroker, service: RecordingService
) -> None:
    topics = Topics("t2")
    bridge = MqttBridge(service, broker.broker, topics, world_rate=50.0, client_id="bridge-t2")
    with Inbox(broker.broker, [topics.world, "t2/errors/+"], "inbox-t2") as inbox:
        assert bridge.start()
        robot = Robot(broker.broker, "robot-t2")
        robot.link.start()
        for step in range(2):
            robot.publish(topics.detections("r1"), scan(0.2 * step))
        wait_until(lambda: len(service.applied) == 2, "two applied batches")
        before = (service.world(), service.hypotheses(1000))
        bad = {"detections": [{"time": 0.4, "class": "Cup", "position": [1.0, 2.0]},
                              {"time": 0.4, "class": "Mug", "position": [1.0, 2.0]},
                              {"time": 0.4, "class": "Cup", "position": [1.0]}]}  # fmt: skip
        robot.publish(topics.detections("r1"), bad)
        robot.link.publish("t2/detections/r2", b"not json")
        wait_until(lambda: len(inbox.on("t2/errors/r2")) == 1, "the error of r2")
        wait_until(lambda: len(inbox.on("t2/errors/r1")) == 1, "the error of r1")
        (error,) = inbox.on("t2/errors/r1")
        assert error["status"] == 422
        assert error["topic"] == "t2/detections/r1"
        assert [item["loc"] for item in error["detail"]] == [
            ["body", "detections", 1, "class"], ["body", "detections", 2, "position"]
        ]  # fmt: skip
        assert "Mug" in error["detail"][0]["msg"]
        assert inbox.on("t2/errors/r2")[0]["detail"][0]["type"] == "json_invalid"
        assert len(service.applied) == 2
        assert (service.world(), service.hypotheses(1000)) == before
        robot.link.stop()
        bridge.stop()
    assert bridge.core.counts.refused == 2


def test_broker_restart_loses_no_acknowledged_batch(
    broker: PrivateBroker, service: RecordingService
) -> None:
    """QoS 1 and persistent sessions: batches acknowledged before, during and after two
    broker restarts, one of them while the bridge is away, are all applied exactly once."""
    topics = Topics("t3")
    robot = Robot(broker.broker, "robot-t3")
    bridge = MqttBridge(service, broker.broker, topics, world_rate=20.0, client_id="bridge-t3")
    assert bridge.start()
    robot.link.start()
    assert robot.link.wait_connected(10)
    times: list[float] = []

    def publish(count: int) -> None:
        for _ in range(count):
            t = round(0.05 * len(times), 6)
            times.append(t)
            robot.publish(topics.detections("r1"),
                          {"time": t, "class": "Cup", "position": [1.0, 2.0]})  # fmt: skip

    publish(10)
    wait_until(robot.all_acknowledged, "the first 10 acknowledgements")
    broker.stop()
    publish(10)  # the broker is down: queued by the robot's client, sent on reconnection
    broker.start()
    publish(10)
    wait_until(robot.all_acknowledged, "30 acknowledgements after the restart")
    wait_until(lambda: len(service.applied) == 30, "30 applied batches")
    # The bridge goes away; what the broker acknowledged meanwhile waits in the bridge's
    # persistent session, across another restart.
    bridge.stop()
    publish(10)
    wait_until(robot.all_acknowledged, "40 acknowledgements")
    broker.stop()
    broker.start()
    again = MqttBridge(service, broker.broker, topics, world_rate=20.0, client_id="bridge-t3")
    assert again.start()
    wait_until(lambda: len(service.applied) >= 40, "40 applied batches")
    time.sleep(0.3)  # a duplicate, if any, would arrive now
    applied = [batch[0]["time"] for batch in service.applied]
    assert len(robot.acknowledged()) == 40
    assert sorted(applied) == sorted(times)  # every acknowledged batch, each once
    robot.link.stop()
    again.stop()


def test_world_topic_rate_limit_holds(broker: PrivateBroker, service: RecordingService) -> None:
    """At `rate` Hz the world topic carries at most 1 + elapsed x rate messages, and the
    last one shows every applied batch."""
    rate = 0.5
    topics = Topics("t4")
    with Inbox(broker.broker, [topics.world], "inbox-t4") as inbox:
        started = time.monotonic()
        bridge = MqttBridge(service, broker.broker, topics, world_rate=rate, client_id="bridge-t4")
        assert bridge.start()
        robot = Robot(broker.broker, "robot-t4")
        robot.link.start()
        for step in range(20):
            robot.publish(topics.detections("r1"), scan(0.05 * step))
        wait_until(lambda: len(service.applied) == 20, "20 applied batches")
        final = bridge.core.world_json()
        wait_until(lambda: inbox.on(topics.world)[-1:] == [final], "the world after batch 20")
        elapsed = time.monotonic() - started
        worlds = inbox.on(topics.world)
        assert 2 <= len(worlds) <= 1 + math.floor(elapsed * rate)
        assert bridge.core.counts.world_published == len(worlds)
        robot.link.stop()
        bridge.stop()


def test_batches_from_mqtt_are_journaled_with_a_data_dir(
    broker: PrivateBroker, tmp_path: Path
) -> None:
    """With --data-dir the bridge applies to the durable model: a restarted service
    (without MQTT) restores what came in over MQTT."""
    topics = Topics("t5")
    data = tmp_path / "data"
    settings = Settings(knowledge=KNOWLEDGE, port=0, data_dir=data, sync="batch",
                        mqtt=broker.url, mqtt_prefix="t5")  # fmt: skip
    with running_server(settings) as url:
        robot = Robot(broker.broker, "robot-t5")
        robot.link.start()
        for step in range(3):
            robot.publish(topics.detections("r1"), scan(0.2 * step))

        def world_at_04() -> bool:
            return bool(httpx.get(f"{url}/world").json()["time"] == 0.4)

        wait_until(world_at_04, "the three batches applied")
        before = httpx.get(f"{url}/world").json()
        robot.link.stop()
    with running_server(Settings(knowledge=KNOWLEDGE, port=0, data_dir=data)) as url:
        assert httpx.get(f"{url}/world").json() == before
    assert len(before["objects"]) == 2
