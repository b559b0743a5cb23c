"""MQTT transport for semwm: topics and payloads (:mod:`semwm.mqtt.protocol`, pure) and
the paho-mqtt connection (:mod:`semwm.mqtt.client`, needs ``pip install "semwm[mqtt]"``).

The protocol is importable without paho-mqtt; the client is not.
"""

from semwm.mqtt.protocol import (
    Broker,
    PayloadError,
    RateLimit,
    RecentMessages,
    Topics,
    decode_json,
    encode_json,
    parse_broker_url,
    with_source,
)

__all__ = [
    "Broker",
    "PayloadError",
    "RateLimit",
    "RecentMessages",
    "Topics",
    "decode_json",
    "encode_json",
    "parse_broker_url",
    "with_source",
]
