"""Helpers of the MQTT tests: a subscriber that collects messages, a robot that counts
its acknowledged publications, and a bounded wait."""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from api.service import Committed, WorldService
from semwm import IngestResult
from semwm.mqtt.protocol import Broker

KNOWLEDGE = Path(__file__).resolve().parents[2] / "knowledge" / "sim1.yaml"
WAIT = 30.0  # s: the longest any wait in these tests may take before it fails


def wait_until(condition: Callable[[], bool], what: str, timeout: float = WAIT) -> None:
    """Poll ``condition`` until it holds; fail naming ``what`` after ``timeout`` seconds."""
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout:g} s waiting for {what}")
        time.sleep(0.02)


class RecordingService(WorldService):
    """A world service that records every batch it applied (the detections as given)."""

    applied: list[list[dict[str, Any]]]

    def ingest(
        self,
        detections: Sequence[dict[str, Any]],
        batch: bool,
        key: str | None = None,
        **options: Any,
    ) -> Committed[IngestResult]:
        result = super().ingest(detections, batch, key=key, **options)
        if not result.replayed:
            self.applied.append([dict(d) for d in detections])
        return result


class Inbox:
    """Every message on ``topics`` (QoS 1), in arrival order."""

    def __init__(self, broker: Broker, topics: list[str], client_id: str) -> None:
        self._lock = threading.Lock()
        self._messages: list[tuple[str, Any]] = []
        from semwm.mqtt.client import MqttLink

        self.link = MqttLink(broker, client_id, subscriptions=topics, on_message=self._add)

    def _add(self, topic: str, payload: bytes) -> None:
        with self._lock:
            self._messages.append((topic, json.loads(payload)))

    def __enter__(self) -> Inbox:
        self.link.start()
        assert self.link.wait_connected(WAIT), "the inbox could not connect"
        return self

    def __exit__(self, *exc: object) -> None:
        self.link.stop()

    def on(self, topic: str) -> list[Any]:
        with self._lock:
            return [payload for t, payload in self._messages if t == topic]


class Robot:
    """Publishes detection batches (QoS 1) and records which ones the broker acknowledged."""

    def __init__(self, broker: Broker, client_id: str) -> None:
        self._lock = threading.Lock()
        self.sent: dict[int, bytes] = {}
        self._acknowledged: set[int] = set()
        from semwm.mqtt.client import MqttLink

        self.link = MqttLink(broker, client_id, on_acknowledged=self._ack)

    def _ack(self, mid: int) -> None:
        with self._lock:
            self._acknowledged.add(mid)

    def publish(self, topic: str, body: Any) -> None:
        payload = json.dumps(body).encode()
        info = self.link.publish(topic, payload)
        with self._lock:
            self.sent[info.mid] = payload

    def acknowledged(self) -> list[bytes]:
        with self._lock:
            return [self.sent[mid] for mid in sorted(self._acknowledged) if mid in self.sent]

    def all_acknowledged(self) -> bool:
        with self._lock:
            return set(self.sent) <= self._acknowledged
