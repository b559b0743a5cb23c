"""The MQTT client at the edge: one paho-mqtt connection with the session semwm needs.

:class:`MqttLink` connects with a fixed client id and a persistent session
(MQTT 3.1.1 ``clean_session=False``), so the broker keeps the subscriptions and
queues QoS 1 messages while the link is away; paho reconnects by itself when the
broker restarts (backing off from 1 s to ``max_reconnect_delay``), re-sends its
unacknowledged QoS 1 messages, and the link re-subscribes on every connect.

:class:`LocalWorldPublisher` is what a robot's local world model uses to publish
its objects on ``<prefix>/local/<robot>``.

Requires the ``mqtt`` extra: ``pip install "semwm[mqtt]"``.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable, Sequence
from typing import Any

from semwm.mqtt.protocol import Broker, Topics, encode_json

try:
    import paho.mqtt.client as paho
    from paho.mqtt.enums import CallbackAPIVersion, MQTTErrorCode
except ImportError as error:  # pragma: no cover - exercised only without the extra
    raise ImportError('semwm.mqtt.client needs paho-mqtt: pip install "semwm[mqtt]"') from error

logger = logging.getLogger("semwm.mqtt")

MessageHandler = Callable[[str, bytes], None]
AckHandler = Callable[[int], None]
QOS = 1


class MqttLink:
    """A persistent-session MQTT connection that reconnects by itself.

    Parameters
    ----------
    broker
        Where the broker listens.
    client_id
        Fixed and unique per participant: the broker keeps this id's session (its
        subscriptions and queued QoS 1 messages) across disconnections.
    subscriptions
        Topic filters subscribed with QoS 1 on every connect.
    on_message
        Called with ``(topic, payload)`` in paho's network thread for every
        message; the message is acknowledged (PUBACK) only after it returns, so a
        handler that applies the message before returning gets at-least-once
        delivery across crashes and broker restarts.
    will
        ``(topic, payload)`` the broker publishes (retained, QoS 1) if the link
        drops without saying goodbye.
    max_reconnect_delay
        The longest wait between reconnection attempts (s).
    max_inflight
        Unacknowledged QoS 1 messages in flight at once (paho's default is 20).
    on_acknowledged
        Called with a published message's id (``publish(...).mid``) when the broker
        acknowledged it (PUBACK): from then on the broker answers for it.
    """

    def __init__(
        self,
        broker: Broker,
        client_id: str,
        *,
        subscriptions: Sequence[str] = (),
        on_message: MessageHandler | None = None,
        will: tuple[str, bytes] | None = None,
        max_reconnect_delay: int = 5,
        max_inflight: int = 100,
        on_acknowledged: AckHandler | None = None,
    ) -> None:
        if not client_id:
            raise ValueError("client_id must not be empty: a persistent session needs an id")
        self.broker = broker
        self.client_id = client_id
        self.subscriptions = tuple(subscriptions)
        self._on_message = on_message
        self._connected = threading.Event()
        self.connects = 0
        self._client = paho.Client(
            CallbackAPIVersion.VERSION2,
            client_id=client_id,
            clean_session=False,
            protocol=paho.MQTTv311,
        )
        self._client.reconnect_delay_set(min_delay=1, max_delay=max_reconnect_delay)
        self._client.max_inflight_messages_set(max_inflight)
        if will is not None:
            self._client.will_set(will[0], will[1], qos=QOS, retain=True)
        self._client.on_connect = self._handle_connect
        self._client.on_disconnect = self._handle_disconnect
        self._client.on_message = self._handle_message
        if on_acknowledged is not None:
            acknowledged = on_acknowledged

            def handle_publish(
                client: paho.Client, userdata: Any, mid: int, reason: Any, properties: Any
            ) -> None:
                acknowledged(mid)

            self._client.on_publish = handle_publish

    # -- lifecycle ------------------------------------------------------------------------------

    def start(self) -> None:
        """Connect in the background (paho's thread); returns at once."""
        self._client.connect_async(self.broker.host, self.broker.port, keepalive=30)
        self._client.loop_start()

    def wait_connected(self, timeout: float) -> bool:
        """Wait up to ``timeout`` seconds for the connection; whether it is up."""
        return self._connected.wait(timeout)

    @property
    def connected(self) -> bool:
        return self._connected.is_set()

    def stop(self, final: tuple[str, bytes] | None = None, timeout: float = 5.0) -> None:
        """Publish ``final`` (retained) if given and connected, then disconnect cleanly."""
        if final is not None and self.connected:
            info = self.publish(final[0], final[1], retain=True)
            try:
                info.wait_for_publish(timeout)
            except (RuntimeError, ValueError):
                logger.warning("could not publish %s before disconnecting", final[0])
        self._client.disconnect()
        self._client.loop_stop()
        self._connected.clear()

    # -- messages -------------------------------------------------------------------------------

    def publish(self, topic: str, payload: bytes, retain: bool = False) -> paho.MQTTMessageInfo:
        """Queue ``payload`` on ``topic`` with QoS 1 (sent now, or when reconnected)."""
        info = self._client.publish(topic, payload, qos=QOS, retain=retain)
        if info.rc not in (MQTTErrorCode.MQTT_ERR_SUCCESS, MQTTErrorCode.MQTT_ERR_NO_CONN):
            logger.warning("publish on %s: %s", topic, paho.error_string(info.rc))
        return info

    def publish_json(self, topic: str, value: Any, retain: bool = False) -> paho.MQTTMessageInfo:
        return self.publish(topic, encode_json(value), retain=retain)

    # -- paho callbacks (network thread) --------------------------------------------------------

    def _handle_connect(
        self, client: paho.Client, userdata: Any, flags: Any, reason: Any, properties: Any
    ) -> None:
        if reason.is_failure:
            logger.warning("MQTT broker %s refused %s: %s", self.broker.url, self.client_id, reason)
            return
        for topic in self.subscriptions:
            client.subscribe(topic, qos=QOS)
        self.connects += 1
        self._connected.set()
        logger.info(
            "MQTT %s connected to %s (session present: %s)",
            self.client_id,
            self.broker.url,
            bool(flags.session_present),
        )

    def _handle_disconnect(
        self, client: paho.Client, userdata: Any, flags: Any, reason: Any, properties: Any
    ) -> None:
        was = self._connected.is_set()
        self._connected.clear()
        if was:
            url = self.broker.url
            logger.warning("MQTT %s lost %s (%s); reconnecting", self.client_id, url, reason)

    def _handle_message(
        self, client: paho.Client, userdata: Any, message: paho.MQTTMessage
    ) -> None:
        if self._on_message is None:
            return
        try:
            self._on_message(message.topic, bytes(message.payload))
        except Exception:  # a bug in a handler must not stop the network thread
            logger.exception("MQTT handler failed on %s", message.topic)


class LocalWorldPublisher:
    """Publishes a robot's local world (the ``GET /world`` JSON) on ``<prefix>/local/<robot>``.

    Each publication is retained with QoS 1, so a global model that (re)subscribes
    gets every robot's latest local world at once.

    Parameters
    ----------
    link
        A started :class:`MqttLink` (its client id is the robot's own).
    robot
        The robot's name: one topic level.
    topics
        The topic names (prefix).
    """

    def __init__(self, link: MqttLink, robot: str, topics: Topics | None = None) -> None:
        self.topics = topics or Topics()
        self.topic = self.topics.local(robot)
        self.link = link

    def publish(self, world: dict[str, Any]) -> paho.MQTTMessageInfo:
        """Publish ``world`` (``WorldState.to_dict()`` or a ``GET /world`` body)."""
        return self.link.publish_json(self.topic, world, retain=True)
