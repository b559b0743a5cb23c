"""The MQTT bridge: detections in from a broker, the world out, through the HTTP path.

``semwm serve --mqtt mqtt://HOST:PORT`` starts one :class:`MqttBridge` in the app's
lifespan. It subscribes to ``<prefix>/detections/+`` and hands each payload to
:func:`api.routes.detections.apply_body`, the function behind ``POST /detections``:
the same validation, the same lock, the same all-or-nothing batches. A refused
payload is logged and published on ``<prefix>/errors/<source>`` with the body HTTP
would answer (422 field paths, or 409); nothing of it is applied. After applied
batches the world (the ``GET /world`` JSON) is published on ``<prefix>/world``,
retained, at most ``world_rate`` times a second, the last change never dropped; the
bridge's counters go to ``<prefix>/status`` (retained) with it.

Delivery is at least once: a message is acknowledged to the broker only after it
was applied or refused, the session is persistent, and a payload already applied
(a QoS 1 re-delivery after a broker restart) is recognised and skipped.

:class:`BridgeCore` is the part without a network (tests drive it directly);
:class:`MqttBridge` joins it to a :class:`semwm.mqtt.client.MqttLink`.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter
from dataclasses import dataclass, field
from typing import Any

from api.errors import ApiError
from api.routes.detections import apply_body
from api.schemas import WorldOut
from api.service import WorldService
from api.settings import Settings
from semwm.mqtt.protocol import (
    Broker,
    PayloadError,
    RateLimit,
    RecentMessages,
    Topics,
    decode_json,
    encode_json,
    error_payload,
    json_error_body,
    parse_broker_url,
    with_source,
)

logger = logging.getLogger("api.mqtt")


@dataclass(frozen=True)
class Refusal:
    """A payload that was not applied: where to report it and what to say."""

    topic: str
    payload: dict[str, Any]


@dataclass
class SourceCounts:
    """What one source sent: batches and detections applied, payloads refused."""

    batches: int = 0
    detections: int = 0
    refused: int = 0


@dataclass
class BridgeCounts:
    """The bridge's counters, published on ``<prefix>/status``."""

    received: int = 0
    applied: int = 0
    detections: int = 0
    refused: int = 0
    duplicates: int = 0
    world_published: int = 0
    refusals: Counter[int] = field(default_factory=Counter)
    sources: dict[str, SourceCounts] = field(default_factory=dict)

    def source(self, name: str) -> SourceCounts:
        return self.sources.setdefault(name, SourceCounts())

    def to_dict(self) -> dict[str, Any]:
        return {
            "received": self.received,
            "applied": self.applied,
            "detections": self.detections,
            "refused": self.refused,
            "refused_by_status": {str(k): v for k, v in sorted(self.refusals.items())},
            "duplicates": self.duplicates,
            "world_published": self.world_published,
            "sources": {
                name: {"batches": c.batches, "detections": c.detections, "refused": c.refused}
                for name, c in sorted(self.sources.items())
            },
        }


class BridgeCore:
    """Applies detection payloads to a :class:`WorldService` and says what to publish.

    Not thread-safe on its own: :class:`MqttBridge` calls :meth:`handle` from
    paho's one network thread and guards :attr:`rate` with its condition.

    Parameters
    ----------
    service
        The world service the HTTP routes use.
    topics
        The topic names (prefix).
    world_rate
        Most world publications per second.
    max_batch
        The largest batch accepted (as ``POST /detections``).
    """

    def __init__(
        self, service: WorldService, topics: Topics, world_rate: float, max_batch: int
    ) -> None:
        self.service = service
        self.topics = topics
        self.max_batch = max_batch
        self.rate = RateLimit(world_rate)
        self.counts = BridgeCounts()
        self._recent = RecentMessages()

    def handle(self, topic: str, payload: bytes) -> Refusal | None:
        """Apply one message; the refusal to publish if it was not applied."""
        source = self.topics.source_of(topic)
        if source is None:
            return None
        self.counts.received += 1
        key = RecentMessages.digest(topic, payload)
        if self._recent.seen(key):
            self.counts.duplicates += 1
            logger.info("skipped a re-delivered payload on %s", topic)
            return None
        try:
            body = with_source(decode_json(payload), source)
            result = apply_body(self.service, body, self.max_batch).value
        except PayloadError as error:
            return self._refuse(topic, source, 422, json_error_body(error), str(error))
        except ApiError as error:
            return self._refuse(topic, source, error.status, error.body(), error.message)
        self._recent.add(key)
        self.counts.applied += 1
        self.counts.detections += result.applied
        counts = self.counts.source(source)
        counts.batches += 1
        counts.detections += result.applied
        self.rate.changed()
        return None

    def _refuse(
        self, topic: str, source: str, status: int, body: dict[str, Any], message: str
    ) -> Refusal:
        self.counts.refused += 1
        self.counts.refusals[status] += 1
        self.counts.source(source).refused += 1
        logger.warning("refused a payload on %s (%d): %s", topic, status, message)
        return Refusal(self.topics.errors(source), error_payload(topic, status, body))

    def world_json(self) -> dict[str, Any]:
        """The world exactly as ``GET /world`` answers it."""
        state = self.service.world()
        out: dict[str, Any] = WorldOut.model_validate(state.to_dict()).model_dump(
            mode="json", by_alias=True
        )
        return out

    def status_json(self, online: bool) -> dict[str, Any]:
        return {"online": online, **self.counts.to_dict()}


class MqttBridge:
    """The bridge between a broker and the service (see the module docstring).

    Parameters
    ----------
    service
        The world service.
    broker
        Where the broker listens.
    topics
        The topic names (prefix).
    world_rate
        Most world publications per second.
    max_batch
        The largest batch accepted.
    client_id
        The bridge's MQTT client id (its persistent session); default
        ``semwm-bridge-<prefix>`` with ``/`` as ``-``.
    """

    def __init__(
        self,
        service: WorldService,
        broker: Broker,
        topics: Topics,
        world_rate: float = 10.0,
        max_batch: int = 10000,
        client_id: str | None = None,
    ) -> None:
        from semwm.mqtt.client import MqttLink

        self.core = BridgeCore(service, topics, world_rate, max_batch)
        self.topics = topics
        self._wake = threading.Condition()
        self._stopping = False
        self.link = MqttLink(
            broker,
            client_id or "semwm-bridge-" + topics.prefix.replace("/", "-"),
            subscriptions=[topics.detections_filter],
            on_message=self._on_message,
            will=(topics.status, encode_json({"online": False})),
        )
        self._publisher = threading.Thread(
            target=self._publish_loop, name="semwm-mqtt-world", daemon=True
        )

    def start(self, connect_timeout: float = 5.0) -> bool:
        """Connect and start publishing; whether the broker answered within the timeout
        (if not, the link keeps trying in the background)."""
        with self._wake:
            self.core.rate.changed()  # replace a stale retained world at once
        self.link.start()
        self._publisher.start()
        connected = self.link.wait_connected(connect_timeout)
        if not connected:
            logger.warning("MQTT broker %s not reachable yet; retrying", self.link.broker.url)
        return connected

    def stop(self) -> None:
        """Stop publishing and disconnect, leaving ``online: false`` on the status topic."""
        with self._wake:
            self._stopping = True
            self._wake.notify_all()
        if self._publisher.is_alive():
            self._publisher.join(10.0)
        with self._wake:
            final = encode_json(self.core.status_json(online=False))
        self.link.stop(final=(self.topics.status, final))

    def _on_message(self, topic: str, payload: bytes) -> None:
        with self._wake:
            refusal = self.core.handle(topic, payload)
            self._wake.notify_all()
        if refusal is not None:
            self.link.publish_json(refusal.topic, refusal.payload)

    def _publish_loop(self) -> None:
        while True:
            with self._wake:
                if self._stopping:
                    return
                due = self.core.rate.due()
                now = time.monotonic()
                if due is None or not self.link.connected:
                    self._wake.wait(None if due is None else 0.1)
                    continue
                if due > now:
                    self._wake.wait(due - now)
                    continue
                self.core.rate.published(now)
                self.core.counts.world_published += 1
            try:
                world = self.core.world_json()
                with self._wake:
                    status = self.core.status_json(online=True)
                self.link.publish_json(self.topics.world, world, retain=True)
                self.link.publish_json(self.topics.status, status, retain=True)
            except Exception:  # keep publishing after a bug in one world
                logger.exception("could not publish the world")


def start_bridge(service: WorldService, settings: Settings) -> MqttBridge:
    """Build and start the bridge ``settings.mqtt`` asks for (the app's lifespan calls it)."""
    if settings.mqtt is None:
        raise ValueError("settings.mqtt is not set: no broker to join")
    bridge = MqttBridge(
        service,
        parse_broker_url(settings.mqtt),
        Topics(settings.mqtt_prefix),
        world_rate=settings.mqtt_world_rate,
        max_batch=settings.max_batch,
        client_id=settings.mqtt_client_id,
    )
    bridge.start()
    return bridge
